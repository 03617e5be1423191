"""lerobot policies on PushT and ALOHA: ACT and Diffusion saved with random weights as trained
ones are (offline, as tests/host/test_worker_env_scenes.py does) run on the scenes unchanged, by
lerobot's feature names. Needs the `gym-envs` worker environment (the scenes) and the
`lerobot-libero` one (lerobot's policy server); CI creates both, elsewhere these tests are
skipped until `python -m openral_mjx.host.envs create ...` has run."""

import os
import subprocess

import pytest
from worker_envs import require_worker_envs

from openral_mjx.evaluation import evaluate
from openral_mjx.host import envs
from openral_mjx.host.pool import _shim_dir

require_worker_envs("gym-envs", "lerobot-libero")
pytestmark = pytest.mark.worker

# name -> (kind, input features, action size)
POLICIES = {
    "pusht_diffusion": (
        "diffusion",
        {"observation.image": [3, 96, 96], "observation.state": [2]},
        2,
    ),
    "pusht_act_keypoints": (
        "act",
        {"observation.environment_state": [16], "observation.state": [2]},
        2,
    ),
    "aloha_act": ("act", {"observation.images.top": [3, 48, 64], "observation.state": [14]}, 14),
}


@pytest.fixture(scope="module")
def policies(tmp_path_factory):
    """Every policy above, built in one process of the lerobot environment."""
    root = tmp_path_factory.mktemp("gym_policies")
    script = "\n".join(
        ["from openral_mjx.host.lerobot_server import build_random_policy as b"]
        + [f"b({k!r}, {str(root / n)!r}, {f!r}, {a})" for n, (k, f, a) in POLICIES.items()]
    )
    env = {**os.environ, "PYTHONPATH": _shim_dir(), "HF_HUB_OFFLINE": "1"}
    python = envs.ensure_env("lerobot-libero")
    proc = subprocess.run([python, "-c", script], env=env, capture_output=True, text=True)
    assert proc.returncode == 0, proc.stderr
    return {name: root / name for name in POLICIES}


def _check(report, steps, budget_ms, factors):
    assert report.n_episodes == 2 and report.policy.startswith("lerobot:")
    for e in report.episodes:
        assert e.metadata["error"] is None and e.steps == steps
        assert e.latency_budget_ms == budget_ms and e.mean_step_latency_ms > 0
        assert set(e.metadata["factors"]) == set(factors)


def test_diffusion_on_pusht_pixels(policies):
    """lerobot's PushT Diffusion inputs: `observation.image` <- `pixels` (96 x 96, lerobot's
    size), `observation.state` <- `agent_pos`."""
    path = policies["pusht_diffusion"]
    report = evaluate("pusht", f"lerobot:{path}", n_envs=2, max_steps=3, options={"n_workers": 1})
    _check(report, 3, 100.0, ("block_x", "block_y", "block_angle", "agent_x", "agent_y"))


def test_act_on_aloha(policies):
    """lerobot's ALOHA ACT inputs: `observation.images.top` <- `top`, `observation.state` <-
    the 14-D `agent_pos` (a 48 x 64 camera here; lerobot's ALOHA policies see 480 x 640)."""
    options = {"task": "AlohaTransferCube-v0", "image_height": 48, "image_width": 64}
    path = policies["aloha_act"]
    report = evaluate("aloha", f"lerobot:{path}", n_envs=2, max_steps=3, options=options)
    assert report.task == "AlohaTransferCube-v0"
    _check(report, 3, 20.0, ("cube_x", "cube_y"))


@pytest.mark.slow
def test_act_on_pusht_keypoints(policies):
    """`observation.environment_state` <- the T's 16 keypoint coordinates."""
    options = {"obs_type": "environment_state_agent_pos", "n_workers": 1}
    path = policies["pusht_act_keypoints"]
    report = evaluate("pusht", f"lerobot:{path}", n_envs=2, max_steps=3, options=options)
    _check(report, 3, 100.0, ("block_x", "block_y", "block_angle", "agent_x", "agent_y"))
