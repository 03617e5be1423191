"""`lerobot:` in the evaluator's process against the same policy through the server: the same
episodes. Runs where lerobot imports in this environment (Python 3.12 with lerobot 0.6: the
GPU machine) and a server interpreter is at hand (the `lerobot-libero` worker environment, or
`OPENRAL_MJX_PYTHON_LEROBOT_LIBERO`); skipped elsewhere (CI's Python 3.11 cannot hold lerobot
0.6, so CI tests the server path: tests/policies/test_lerobot_chunks.py)."""

import importlib.util
import os

import numpy as np
import pytest

from openral_mjx.host import envs
from openral_mjx.policies import make_policy
from openral_mjx.runner import run_seeds

if importlib.util.find_spec("lerobot") is None:
    pytest.skip("lerobot does not import in this environment", allow_module_level=True)
if not (os.environ.get("OPENRAL_MJX_PYTHON_LEROBOT_LIBERO") or envs.is_ready("lerobot-libero")):
    pytest.skip("no lerobot server interpreter", allow_module_level=True)


@pytest.fixture(scope="module")
def act_dir(tmp_path_factory, push_c):
    from openral_mjx.host.lerobot_server import build_random_policy

    path = tmp_path_factory.mktemp("act") / "act"
    size = int(np.prod(push_c.observation_spec.shape))
    features = {"observation.state": [size], "observation.environment_state": [size]}
    build_random_policy("act", str(path), features, push_c.action_size, seed=3)
    return path


@pytest.mark.parametrize("batching", ["chunks", "refill"])
def test_in_process_and_server_give_the_same_episodes(push_c, act_dir, monkeypatch, batching):
    results = {}
    for mode in ("process", "server"):
        monkeypatch.setenv("OPENRAL_MJX_LEROBOT", mode)
        policy = make_policy(f"lerobot:{act_dir}", push_c)
        try:
            assert not policy.aligned_episodes
            results[mode], _ = run_seeds(
                push_c, policy, None, seeds=np.arange(8), n_envs=4, max_steps=20, batching=batching
            )
        finally:
            if policy.close is not None:
                policy.close()
    got, ref = results["process"], results["server"]
    np.testing.assert_array_equal(got["steps"], ref["steps"])
    np.testing.assert_array_equal(got["success"], ref["success"])
    np.testing.assert_allclose(got["total_reward"], ref["total_reward"], rtol=1e-5, atol=1e-6)
