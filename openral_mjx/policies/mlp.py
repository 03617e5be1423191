"""`mlp`: a flax Gaussian MLP policy, and its checkpoints (orbax params + a JSON config).

The network maps normalised observations to the mean `u` of a diagonal Gaussian (with a
learned, state-independent log standard deviation) in a unit-scaled action space; the action is

    action = base(obs) + offset + scale * u,

where `base(obs)` reads each actuator's current joint position from the observation when the
scene provides it (`Scene.action_obs_index`: position servos act relative to where the joint
is) and is 0 otherwise, and `offset`/`scale` put `u` on the scale of typical actions (set from
the demonstrations in behaviour cloning). Evaluation takes the mean by default.

A checkpoint directory holds `mlp_policy.json` (`MlpConfig`: sizes, action mapping,
normalisation settings, provenance) and `params/` (orbax: network params and the observation
normaliser's statistics), so `--policy mlp:DIR` needs nothing else.
"""

from __future__ import annotations

import dataclasses
import json
import os
import shutil
from collections.abc import Sequence
from pathlib import Path
from typing import Any

import flax.linen as nn
import jax
import jax.numpy as jnp

from openral_mjx.core import fixed_order as fo
from openral_mjx.core.checkpoints import restore_tree, save_tree
from openral_mjx.core.errors import ConfigError, unknown
from openral_mjx.core.files import write_json_atomic
from openral_mjx.policies.base import Policy
from openral_mjx.policies.normalizer import RunningStats, init_stats, normalize

MLP_FORMAT = "openral_mjx.mlp_policy/1"
CONFIG_FILE = "mlp_policy.json"
PARAMS_DIR = "params"
PARAMS_DIGESTS = "params_sha256"
ACTIVATIONS = {"silu": nn.silu, "tanh": nn.tanh, "relu": nn.relu}


def check_architecture(hidden: Sequence[int], activation: str) -> None:
    """Reject an empty or non-positive layer list, or an unknown activation."""
    if activation not in ACTIVATIONS:
        raise unknown("activation", activation, ACTIVATIONS)
    if not hidden or min(hidden) < 1:
        raise ConfigError(f"hidden layer sizes must be positive, got {list(hidden)}")


@dataclasses.dataclass(frozen=True)
class MlpConfig:
    """Everything besides the arrays needed to rebuild and run a saved `mlp` policy."""

    obs_size: int
    action_size: int
    action_offset: tuple[float, ...]
    action_scale: tuple[float, ...]
    action_base_index: tuple[int, ...] | None = None
    hidden: tuple[int, ...] = (256, 256, 256)
    activation: str = "silu"
    obs_std_min: float = 0.01
    obs_clip: float = 10.0
    metadata: dict[str, Any] = dataclasses.field(default_factory=dict, compare=False)

    def __post_init__(self) -> None:
        check_architecture(self.hidden, self.activation)
        n = self.action_size
        if len(self.action_offset) != n or len(self.action_scale) != n:
            raise ConfigError(f"action_offset and action_scale need {n} values each")
        if min(self.action_scale) <= 0:
            raise ConfigError(f"action_scale must be > 0, got {list(self.action_scale)}")
        base = self.action_base_index
        if base is not None and (len(base) != n or not all(0 <= i < self.obs_size for i in base)):
            raise ConfigError(
                f"action_base_index {list(base)} needs {n} indices into an observation "
                f"of size {self.obs_size}"
            )

    def to_json(self) -> dict[str, Any]:
        return {"format": MLP_FORMAT, **dataclasses.asdict(self)}

    @classmethod
    def from_json(cls, data: Any) -> MlpConfig:
        if not isinstance(data, dict):
            raise ConfigError("not a JSON object")
        data = dict(data)
        if data.pop("format", None) != MLP_FORMAT:
            raise ConfigError(f"not an {MLP_FORMAT} config")
        names = {f.name for f in dataclasses.fields(cls)}
        if set(data) - names:
            raise ConfigError(f"unknown config fields {sorted(set(data) - names)}")
        for key in ("action_offset", "action_scale", "action_base_index", "hidden"):
            if isinstance(data.get(key), list):
                data[key] = tuple(data[key])
        try:
            return cls(**data)
        except TypeError as e:
            raise ConfigError(f"incomplete config: {e}") from None


class _Dense(nn.Module):
    """`nn.Dense`'s parameters; the product is XLA's, or `fixed_order.dense` for one vector."""

    features: int
    fixed_order: bool = False
    kernel_init: Any = nn.initializers.lecun_normal()

    @nn.compact
    def __call__(self, x: jax.Array) -> jax.Array:
        kernel = self.param("kernel", self.kernel_init, (x.shape[-1], self.features))
        bias = self.param("bias", nn.initializers.zeros, (self.features,))
        if self.fixed_order:
            return fo.dense(x, kernel, bias)
        return x @ kernel + bias


class GaussianMLP(nn.Module):
    """Normalised observation -> (mean of `u`, log std of `u`), per action dimension.

    `fixed_order` computes the layers with `fixed_order.dense` (single observation only), so
    an evaluated episode does not depend on the batch size; training uses XLA's products.
    """

    hidden: Sequence[int]
    action_size: int
    activation: str = "silu"
    fixed_order: bool = False
    init_log_std: float = 0.0

    @nn.compact
    def __call__(self, x: jax.Array) -> tuple[jax.Array, jax.Array]:
        act = ACTIVATIONS[self.activation]
        for size in self.hidden:
            x = act(_Dense(size, self.fixed_order)(x))
        # A small last layer starts an untrained policy near `u = 0` (hold the joints).
        small = nn.initializers.variance_scaling(0.01, "fan_in", "truncated_normal")
        mean = _Dense(self.action_size, self.fixed_order, kernel_init=small)(x)
        log_std = self.param(
            "log_std", nn.initializers.constant(self.init_log_std), (self.action_size,)
        )
        return mean, log_std


def network(config: MlpConfig, *, fixed_order: bool = False) -> GaussianMLP:
    return GaussianMLP(
        hidden=tuple(config.hidden),
        action_size=config.action_size,
        activation=config.activation,
        fixed_order=fixed_order,
    )


def init_params(
    config: MlpConfig, key: jax.Array, normalizer: RunningStats | None = None
) -> dict[str, Any]:
    """Fresh params: `{"actor": flax variables, "normalizer": RunningStats}`."""
    obs = jnp.zeros(config.obs_size, jnp.float32)
    return {
        "actor": network(config).init(key, obs),
        "normalizer": normalizer if normalizer is not None else init_stats(config.obs_size),
    }


def normalized_obs(config: MlpConfig, params: dict[str, Any], obs: jax.Array) -> jax.Array:
    return normalize(params["normalizer"], obs, config.obs_std_min, config.obs_clip)


def distribution(
    config: MlpConfig, params: dict[str, Any], obs: jax.Array, *, fixed_order: bool = False
) -> tuple[jax.Array, jax.Array]:
    """Mean and log std of `u` for raw observation(s) `obs` (normalised here)."""
    return network(config, fixed_order=fixed_order).apply(
        params["actor"], normalized_obs(config, params, obs)
    )


def to_action(config: MlpConfig, obs: jax.Array, u: jax.Array) -> jax.Array:
    """Map unit-scaled `u` to the scene's action (`base(obs) + offset + scale * u`)."""
    action = (
        jnp.asarray(config.action_offset, jnp.float32)
        + jnp.asarray(config.action_scale, jnp.float32) * u
    )
    if config.action_base_index is not None:
        action = action + obs[..., jnp.asarray(config.action_base_index)]
    return action


def mlp_policy(
    config: MlpConfig, params: dict[str, Any] | None = None, *, deterministic: bool = True
) -> Policy:
    """The runner-facing policy: `init` hands out `params` (None: the caller passes its own to
    the runner); `act` takes the mean by default (or samples `u` when not `deterministic`), in
    fixed-order arithmetic."""

    def init(key, obs_spec):
        del key, obs_spec
        return params, jnp.zeros((), jnp.int32)

    def act(p, pstate, obs, key):
        mean, log_std = distribution(config, p, obs, fixed_order=True)
        u = mean if deterministic else mean + jnp.exp(log_std) * jax.random.normal(key, mean.shape)
        return to_action(config, obs, u), pstate

    return Policy("mlp" if deterministic else "mlp-sample", init, act)


def save_mlp(directory: Path, config: MlpConfig, params: dict[str, Any]) -> None:
    """Write a checkpoint directory; built aside and swapped in, so never half-written."""
    directory = Path(directory)
    directory.parent.mkdir(parents=True, exist_ok=True)
    tmp = directory.with_name(f".{directory.name}.tmp-{os.getpid()}")
    old = directory.with_name(f".{directory.name}.old-{os.getpid()}")
    shutil.rmtree(tmp, ignore_errors=True)
    digests = save_tree(tmp / PARAMS_DIR, params)
    write_json_atomic(tmp / CONFIG_FILE, {**config.to_json(), PARAMS_DIGESTS: digests})
    if directory.exists():
        directory.rename(old)
    tmp.rename(directory)
    shutil.rmtree(old, ignore_errors=True)


def load_mlp(directory: Path) -> tuple[MlpConfig, dict[str, Any]]:
    """Read a checkpoint directory; any defect is a one-line `ConfigError` naming it."""
    directory = Path(directory)
    name = str(directory)
    if not directory.is_dir():
        raise ConfigError(f"mlp checkpoint {name!r} does not exist")
    path = directory / CONFIG_FILE
    if not path.is_file():
        inner = [str(directory / d) for d in ("best", "final") if (directory / d).is_dir()]
        hint = f"; did you mean {' or '.join(inner)}?" if inner else ""
        raise ConfigError(f"{name!r} is not an mlp checkpoint (no {CONFIG_FILE}){hint}")
    try:
        data = json.loads(path.read_text())
        digests = data.pop(PARAMS_DIGESTS, None) if isinstance(data, dict) else None
        config = MlpConfig.from_json(data)
    except (json.JSONDecodeError, UnicodeDecodeError) as e:
        raise ConfigError(f"mlp checkpoint {name!r}: {CONFIG_FILE} is not JSON: {e}") from None
    except ConfigError as e:
        raise ConfigError(f"mlp checkpoint {name!r}: {CONFIG_FILE}: {e}") from None
    template = jax.eval_shape(lambda: init_params(config, jax.random.PRNGKey(0)))
    params = restore_tree(directory / PARAMS_DIR, template, "mlp checkpoint params", digests)
    return config, params


def check_compatible(config: MlpConfig, scene: Any, source: str) -> None:
    """Reject a policy built for other observation or action sizes than `scene`'s."""
    if (config.obs_size, config.action_size) != (scene.observation_size, scene.action_size):
        built = config.metadata.get("scene", "another scene")
        raise ConfigError(
            f"{source} was built for observation size {config.obs_size} and action size "
            f"{config.action_size} ({built}); scene {scene.name!r} has "
            f"{scene.observation_size} and {scene.action_size}"
        )
