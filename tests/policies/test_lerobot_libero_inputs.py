"""`lerobot:` in process on a LIBERO observation (the mirror's dict with cameras), without
lerobot: `LerobotRunner`'s own batch conversion and chunking behind the torch bridge, with a
recording stand-in for the lerobot policy. What lerobot's LIBERO env itself hands a policy is
checked in the worker tier (tests/benchmarks/libero/test_libero_mjx_lerobot.py)."""

from __future__ import annotations

import json
from types import SimpleNamespace
from typing import Any

import jax
import jax.numpy as jnp
import numpy as np
import pytest

from openral_mjx.host import lerobot_server
from openral_mjx.policies.lerobot import lerobot_policy

torch = pytest.importorskip("torch")

SD = jax.ShapeDtypeStruct
SIZE = 16
IMAGES = ("observation.images.image", "observation.images.image2")
FEATURES = {**{k: [3, SIZE, SIZE] for k in IMAGES}, "observation.state": [8]}
# libero_mjx's observation with `image_size` (`mirror.scene`): the cameras, state and expert
LIBERO_MJX_OBS = {
    "image": SD((SIZE, SIZE, 3), jnp.uint8),
    "wrist_image": SD((SIZE, SIZE, 3), jnp.uint8),
    "state": SD((8,), jnp.float32),
    "expert": SD((10,), jnp.float32),
}


class RecordingRunner(lerobot_server.LerobotRunner):
    """`LerobotRunner` with lerobot's policy and processors replaced: identity processors and
    a chunk of the state's first 7 values, each batch the policy gets recorded."""

    batches: list[dict[str, Any]] = []  # noqa: RUF012 (reset by the test)

    def __init__(self, path: str, device: str | None = None, seed: int = 0) -> None:
        self.torch, self.device, self.seed = torch, "cpu", seed
        self.visual = set(IMAGES)
        self.n_action_steps, self.per_env = 2, True
        self.chunk = self.index = None
        self.pre = self.post = lambda x: x
        self.policy = SimpleNamespace(predict_action_chunk=self._chunk)

    def _chunk(self, batch: dict[str, Any]) -> Any:
        RecordingRunner.batches.append(
            {k: v if k == "task" else v.clone() for k, v in batch.items()}
        )
        return batch["observation.state"][:, None, :7].repeat(1, self.n_action_steps, 1)


def test_the_mirrors_cameras_reach_a_lerobot_policy_in_process(tmp_path, monkeypatch):
    """Through DLPack: each LIBERO feature gets its observation (the wrist camera
    `wrist_image` as `image2`), images as float (n, C, H, W) in [0, 1] from the uint8
    (H, W, C), the state as is, the instruction as `task`; the `expert` entry stays out."""
    config = {
        "input_features": {
            k: {"type": "VISUAL" if k in IMAGES else "STATE", "shape": v}
            for k, v in FEATURES.items()
        },
        "output_features": {"action": {"type": "ACTION", "shape": [7]}},
    }
    (tmp_path / "config.json").write_text(json.dumps(config))
    scene = SimpleNamespace(
        name="libero_mjx",
        observation_spec=LIBERO_MJX_OBS,
        action_size=7,
        instruction="put the bowl on the plate",
        options=SimpleNamespace(image_size=SIZE),
    )
    monkeypatch.setenv("OPENRAL_MJX_LEROBOT", "process")
    monkeypatch.setenv("OPENRAL_MJX_TORCH_DEVICE", "cpu")
    monkeypatch.setattr(lerobot_server, "LerobotRunner", RecordingRunner)
    RecordingRunner.batches = []
    policy = lerobot_policy(scene, str(tmp_path))
    assert policy.name == f"lerobot:{tmp_path}" and not policy.aligned_episodes

    n = 3
    rng = np.random.default_rng(0)
    obs = {
        k: jnp.asarray(
            rng.integers(0, 256, (n, *v.shape))
            if v.dtype == jnp.uint8
            else rng.normal(size=(n, *v.shape)),
            v.dtype,
        )
        for k, v in LIBERO_MJX_OBS.items()
    }
    _, pstate = jax.vmap(lambda k: policy.init(k, None))(jax.random.split(jax.random.PRNGKey(0), n))
    act = jax.jit(jax.vmap(lambda s, o: policy.act(None, s, o, None)))
    action, pstate = act(pstate, obs)

    (batch,) = RecordingRunner.batches
    assert set(batch) == {*FEATURES, "task"}
    assert batch["task"] == [scene.instruction] * n
    for feature, key in zip(IMAGES, ("image", "wrist_image"), strict=True):
        got = batch[feature].numpy()
        assert got.dtype == np.float32 and got.shape == (n, 3, SIZE, SIZE)
        want = np.asarray(obs[key]).transpose(0, 3, 1, 2) / np.float32(255)
        np.testing.assert_allclose(got, want, rtol=1e-6)
    np.testing.assert_array_equal(batch["observation.state"].numpy(), np.asarray(obs["state"]))
    np.testing.assert_allclose(np.asarray(action), np.asarray(obs["state"])[:, :7], rtol=1e-6)
    np.testing.assert_array_equal(np.asarray(pstate["t"]), np.ones(n, np.int32))
