"""`depth_cnn`: a small flax policy that looks at a depth image, to show vision in the loop.

The image (a depth slice of the flat observation, metres) is average-pooled to at most 16
pixels across, passed through one 3x3 convolution (8 channels, ReLU), pooled 2x2, and joined
with the joint positions in a small MLP whose output sets each actuator's position target
within a quarter of its range around the middle. Weights are random (from the evaluation's
seed): the policy is not meant to succeed, only to act on what the camera sees, inside the
same `jit` as the physics and the ray-cast (or rendered) camera.

Every layer is elementwise arithmetic in a fixed order (pooling and the convolution as sums of
shifted slices, dense layers with `fixed_order.dense`), so an episode does not depend on the
batch size, like the scenes' other observations.
"""

from __future__ import annotations

from collections.abc import Mapping

import flax.linen as nn
import jax
import jax.numpy as jnp

from openral_mjx.core import fixed_order as fo
from openral_mjx.core.errors import ConfigError
from openral_mjx.policies.base import Policy

_MAX_WIDTH = 16  # pixels across after the first pooling
_CHANNELS = 8
_HIDDEN = 32


def _pool(x: jax.Array, p: int) -> jax.Array:
    """Average over p x p blocks of the leading two axes (cropping a remainder)."""
    h, w = x.shape[0] // p, x.shape[1] // p
    x = x[: h * p, : w * p]
    total = None
    for dy in range(p):
        for dx in range(p):
            part = x[dy::p, dx::p]
            total = part if total is None else total + part
    return total / (p * p)


class DepthCNN(nn.Module):
    """(depth image (H, W), joint positions) -> unit actions in (-1, 1)."""

    action_size: int

    @nn.compact
    def __call__(self, depth: jax.Array, joints: jax.Array) -> jax.Array:
        p = max(1, -(-depth.shape[1] // _MAX_WIDTH))
        x = _pool(depth, p)[..., None]  # (h, w, 1)
        kernel = self.param("conv", nn.initializers.lecun_normal(), (3, 3, 1, _CHANNELS))
        bias = self.param("conv_bias", nn.initializers.zeros, (_CHANNELS,))
        h, w = x.shape[0] - 2, x.shape[1] - 2
        y = bias
        for dy in range(3):
            for dx in range(3):
                y = y + x[dy : dy + h, dx : dx + w, :] * kernel[dy, dx, 0]
        y = _pool(jax.nn.relu(y), 2) if min(h, w) >= 2 else jax.nn.relu(y)
        features = jnp.concatenate([y.reshape(-1), joints])
        w1 = self.param("dense", nn.initializers.lecun_normal(), (features.shape[0], _HIDDEN))
        b1 = self.param("dense_bias", nn.initializers.zeros, (_HIDDEN,))
        w2 = self.param("out", nn.initializers.lecun_normal(), (_HIDDEN, self.action_size))
        b2 = self.param("out_bias", nn.initializers.zeros, (self.action_size,))
        return jnp.tanh(fo.dense(jnp.tanh(fo.dense(features, w1, b1)), w2, b2))


def depth_cnn_policy(
    obs_layout: Mapping[str, tuple[int, int]],
    obs_shapes: Mapping[str, tuple[int, ...]],
    low: jax.Array,
    high: jax.Array,
    image: str | None = None,
) -> Policy:
    """The policy reading depth slice `image` (default: the observation's first depth image)
    and `joint_pos`; actions within [low, high]."""
    depths = [k for k, shape in obs_shapes.items() if len(shape) == 2]
    if image is None:
        if not depths:
            raise ConfigError(
                "policy 'depth_cnn' needs a depth image in the observation; add one with "
                "--opt 'obs_depth_cameras=[overhead]'"
            )
        image = depths[0]
    if image not in depths:
        raise ConfigError(f"unknown depth image {image!r}; valid: {', '.join(depths) or '(none)'}")
    start, size = obs_layout[image]
    shape = obs_shapes[image]
    j0, nj = obs_layout["joint_pos"]
    net = DepthCNN(action_size=low.shape[0])
    mid, half = (high + low) / 2, (high - low) / 2

    def split(obs: jax.Array) -> tuple[jax.Array, jax.Array]:
        return obs[start : start + size].reshape(shape), obs[j0 : j0 + nj]

    def init(key: jax.Array, obs_spec: jax.ShapeDtypeStruct):
        params = net.init(key, *split(jnp.zeros(obs_spec.shape, obs_spec.dtype)))
        return params, ()

    def act(params, state, obs: jax.Array, key: jax.Array):
        del key
        return mid + 0.25 * half * net.apply(params, *split(obs)), state

    # The traced code depends on the scene (layout, bounds) and the image read, not the weights.
    return Policy(name="depth_cnn", init=init, act=act, cache_key=f"depth_cnn:{image}")
