"""A lerobot policy saved for LIBERO, unchanged, on `libero_mjx` with its cameras.

A random-weight ACT with LIBERO's input features (lerobot's ``observation.images.image``,
``observation.images.image2``, ``observation.state``) runs on the mirror, its image size taken
from its config. What it receives is recorded at the policy server and checked against
lerobot's own LIBERO env (`data/lerobot_libero_reference.py`: lerobot's `LiberoEnv`,
`preprocess_observation` and `LiberoProcessorStep`), reset to the same seeds and playing the
actions the policy sent to the mirror: the same feature names, shapes, dtype and scaling, the
images the same way up and within 8/255 almost everywhere, the same state and task string.
Seeds replayed in the other batch slot give bit-identical inputs and actions; a small
Diffusion (slow tier: another compile) gets the same episodes per seed when run twice.
The ACT part (the worker and heavy tiers) takes ~105 s on 2 cores, most of it the mirror's
compile with its cameras on `c` (its host callbacks are not cacheable) and two lerobot imports;
it took 346 s at load 6-7 before the tests compiled unoptimised (docs/tests.md).
"""

from __future__ import annotations

import os
import subprocess
from pathlib import Path
from types import SimpleNamespace
from typing import Any, ClassVar

import numpy as np
import pytest
from worker_envs import require_worker_envs

from openral_mjx.evaluation import build_scene
from openral_mjx.host import envs
from openral_mjx.host.lerobot_server import LerobotRunner
from openral_mjx.host.pool import Worker, _shim_dir
from openral_mjx.policies import lerobot, make_policy
from openral_mjx.runner import run_seeds
from openral_mjx.scenes import SCENES

ENV = "lerobot-libero"
require_worker_envs(ENV)
pytestmark = [pytest.mark.worker, pytest.mark.heavy]

TASK = "libero_spatial/0"
SIZE = 32
STEPS = 3
FEATURES = {
    "observation.images.image": [3, SIZE, SIZE],
    "observation.images.image2": [3, SIZE, SIZE],
    "observation.state": [8],
}
REFERENCE = Path(__file__).parents[2] / "data" / "lerobot_libero_reference.py"
MIN_WITHIN = 0.97  # share of pixels within 8/255, as test_libero_render's bound at 32 x 32
GL = {"MUJOCO_GL": "egl", "PYOPENGL_PLATFORM": "egl"}


def _lerobot(args: list[str]) -> None:
    env = {**os.environ, **GL, "PYTHONPATH": _shim_dir(), "HF_HUB_OFFLINE": "1"}
    proc = subprocess.run(
        [envs.ensure_env(ENV), *args], env=env, capture_output=True, text=True, timeout=600
    )
    assert proc.returncode == 0, proc.stdout + proc.stderr


class RecordingWorker(Worker):
    """The policy server's worker, keeping every `act` request (the inputs the policy gets,
    renamed to its features) and the actions it answers."""

    calls: ClassVar[list[dict[str, Any]]] = []

    def call(self, msg: dict[str, Any], timeout: float | None) -> Any:
        reply = super().call(msg, timeout)
        if msg.get("method") == "act":
            kwargs = msg["kwargs"]
            obs = {k: np.array(v) for k, v in kwargs["obs"].items()}
            RecordingWorker.calls.append(
                {"obs": obs, "steps": list(kwargs["steps"]), "task": kwargs["task"]}
                | {"action": np.array(reply["action"])}
            )
        return reply


def _build(kind: str, path: Path) -> str:
    """A small random-weight `kind` policy with LIBERO's features, saved at `path`."""
    build = "from openral_mjx.host.lerobot_server import build_random_policy as b; "
    _lerobot(["-c", build + f"b({kind!r}, {str(path)!r}, {FEATURES!r}, 7, seed=5)"])
    return f"lerobot:{path}"


def _on_mirror(spec: str, seeds: list[int]) -> SimpleNamespace:
    """`spec` on the mirror, `seeds` in chunks of two envs (one compile), through the policy
    server: the recorded calls, the per-seed results, the options the policy implied."""
    options = {"task": TASK}
    implied = lerobot.implied_camera_options(spec, SCENES.get("libero_mjx").options_cls, options)
    scene = build_scene("libero_mjx", {**options, **implied}, backend="c", n_envs=2, threads=2)
    RecordingWorker.calls = []
    with pytest.MonkeyPatch.context() as mp:
        mp.setenv("OPENRAL_MJX_LEROBOT", "server")  # the server path, where the recorder sits
        mp.setattr(lerobot, "Worker", RecordingWorker)
        policy = make_policy(spec, scene)
        try:
            results, _ = run_seeds(
                scene, policy, None, seeds=np.array(seeds), n_envs=2, max_steps=STEPS
            )
        finally:
            policy.close()
            scene.close()
    calls = list(RecordingWorker.calls)
    return SimpleNamespace(calls=calls, results=results, implied=implied, scene=scene)


@pytest.fixture(scope="module")
def run(tmp_path_factory):
    """ACT on the mirror for seeds 0, 1 then 1, 0 (two chunks of two envs, one compile)."""
    root = tmp_path_factory.mktemp("libero_act")
    out = _on_mirror(_build("act", root / "act"), [0, 1, 1, 0])
    out.root = root
    return out


@pytest.fixture(scope="module")
def reference(run):
    """lerobot's LIBERO env from seeds 0 and 1, playing the actions ACT sent to the mirror."""
    first = run.calls[:STEPS]  # the first chunk: seeds 0 and 1
    actions = np.stack([c["action"] for c in first], axis=1)  # (2, STEPS, 7)
    src, dst = run.root / "in.npz", run.root / "out.npz"
    np.savez(src, task=np.array(TASK), size=np.array(SIZE), seeds=np.array([0, 1]), actions=actions)
    _lerobot([str(REFERENCE), str(src), str(dst)])
    return dict(np.load(dst))


def _as_lerobot_batch(obs: dict[str, np.ndarray]) -> dict[str, np.ndarray]:
    """The server's conversion (`LerobotRunner.batch`) of recorded inputs: lerobot's tensors."""
    torch = pytest.importorskip("torch")
    visual = {k for k in obs if k.startswith("observation.images.")}
    runner = SimpleNamespace(device="cpu", visual=visual, torch=torch)
    tensors = {k: torch.from_numpy(v) for k, v in obs.items()}
    return {k: v.numpy() for k, v in LerobotRunner.batch(runner, tensors, None).items()}


def test_the_policys_image_size_is_implied(run):
    assert run.implied == {"image_size": SIZE}
    assert len(run.calls) == 2 * STEPS  # one batched call per control step and chunk
    assert [c["steps"] for c in run.calls] == [[t, t] for t in range(STEPS)] * 2


def test_the_policy_gets_what_lerobots_libero_env_hands_it(run, reference):
    """Names, shapes, dtypes, orientation, scaling, state and task as lerobot's LIBERO env
    and processors give them, from the same seeds under the same actions."""
    assert {c["task"] for c in run.calls} == {str(reference["task"])}
    assert str(reference["task"]) == run.scene.instruction
    for t, call in enumerate(run.calls[:STEPS]):
        obs = call["obs"]
        assert set(obs) == set(FEATURES)
        for name in ("observation.images.image", "observation.images.image2"):
            assert obs[name].dtype == np.uint8 and obs[name].shape == (2, SIZE, SIZE, 3)
        got = _as_lerobot_batch(obs)
        for name, shape in FEATURES.items():
            want = reference[name][:, t]
            assert got[name].shape == want.shape == (2, *shape) and got[name].dtype == np.float32
        np.testing.assert_allclose(
            got["observation.state"], reference["observation.state"][:, t], atol=1e-4
        )
        for name in ("observation.images.image", "observation.images.image2"):
            ours, want = got[name], reference[name][:, t]
            within = (np.abs(ours - want).max(axis=1) <= 8 / 255 + 1e-6).mean()
            assert within >= MIN_WITHIN, (name, t, within)
            err = np.abs(ours - want).mean()
            for turned in (want[..., ::-1, :], want[..., ::-1], want[..., ::-1, ::-1]):
                assert err < np.abs(ours - turned).mean(), (name, t)  # the same way up
    # the actions reached the env: the reference played them, and the arm moved with them
    first = np.stack([c["action"] for c in run.calls[:STEPS]])
    assert np.abs(first[..., :6]).max() > 0.05
    moved = reference["observation.state"][:, -1, :3] - reference["observation.state"][:, 0, :3]
    assert np.linalg.norm(moved, axis=-1).min() > 1e-3


def test_each_seed_gets_the_same_inputs_and_actions_in_either_slot(run):
    """Seeds 0, 1 then 1, 0: each seed's inputs, actions and result are bit-identical."""
    for t in range(STEPS):
        a, b = run.calls[t], run.calls[STEPS + t]
        for key in FEATURES:
            np.testing.assert_array_equal(a["obs"][key], b["obs"][key][::-1])
        np.testing.assert_array_equal(a["action"], b["action"][::-1])
    r = run.results
    for key in ("success", "steps", "total_reward"):
        np.testing.assert_array_equal(np.asarray(r[key])[:2], np.asarray(r[key])[2:][::-1])


@pytest.mark.slow  # another compile of the mirror and a Diffusion: ~60 s more on 2 cores
def test_diffusion_samples_the_same_episodes_per_seed(tmp_path):
    """A small Diffusion (two observation steps, noise drawn for the whole batch) runs on the
    mirror in aligned chunks; seeds 0, 1 played twice get bit-identical inputs and actions
    (its runner reseeds torch when every env starts)."""
    out = _on_mirror(_build("diffusion", tmp_path / "diffusion"), [0, 1, 0, 1])
    assert out.implied == {"image_size": SIZE} and len(out.calls) == 2 * STEPS
    for t in range(STEPS):
        a, b = out.calls[t], out.calls[STEPS + t]
        assert set(a["obs"]) == set(FEATURES)
        for key in FEATURES:
            np.testing.assert_array_equal(a["obs"][key], b["obs"][key])
        np.testing.assert_array_equal(a["action"], b["action"])
