"""lerobot action chunks per env: `LerobotRunner` against lerobot's own `select_action`, and
what the evaluator does with policies that must keep envs aligned.

References: lerobot's `select_action` on the same observations (together, and each env alone
from its own reset), and the chunked runner's episodes for the refilled ones. Needs the
`lerobot-libero` worker environment (lerobot 0.4.4; CI creates it), elsewhere skipped.
"""

import os
import subprocess
from pathlib import Path

import numpy as np
import pytest
from worker_envs import require_worker_envs

from openral_mjx.core.errors import ConfigError
from openral_mjx.host import envs
from openral_mjx.host.pool import _shim_dir
from openral_mjx.policies import make_policy
from openral_mjx.runner import resolve_batching, run_seeds

ENV = "lerobot-libero"
require_worker_envs(ENV)
pytestmark = pytest.mark.worker

CHECK = Path(__file__).parents[1] / "data" / "lerobot_chunks_check.py"


def _lerobot(args: list[str]) -> subprocess.CompletedProcess:
    env = {**os.environ, "PYTHONPATH": _shim_dir(), "HF_HUB_OFFLINE": "1"}
    python = envs.ensure_env(ENV)
    return subprocess.run([python, *args], env=env, capture_output=True, text=True, timeout=600)


@pytest.fixture(scope="module")
def push_policies(tmp_path_factory, push_c):
    """One lerobot process: the per-env chunk check (`data/lerobot_chunks_check.py`), then a
    small ACT and a Diffusion policy (two observation steps) on `tabletop_push`'s observation
    vector. The policies' folder and the check's output."""
    root = tmp_path_factory.mktemp("push_policies")
    size = int(np.prod(push_c.observation_spec.shape))
    # ACT needs an image or an environment state: both state features read the flat vector
    features = {"observation.state": [size], "observation.environment_state": [size]}
    script = "\n".join(
        [
            f"import sys; sys.path.insert(0, {str(CHECK.parent)!r})",
            "import lerobot_chunks_check as check",
            f"check.main({str(root / 'check')!r})",
            "from openral_mjx.host.lerobot_server import build_random_policy as b",
            f"b('act', {str(root / 'act')!r}, {features!r}, {push_c.action_size})",
            f"b('diffusion', {str(root / 'diffusion')!r}, {features!r}, {push_c.action_size})",
        ]
    )
    proc = _lerobot(["-c", script])
    assert proc.returncode == 0, proc.stdout + proc.stderr
    return root, proc.stdout


def test_per_env_chunks_are_lerobots_own(push_policies):
    """See `data/lerobot_chunks_check.py`: together, exactly `select_action` on the batch;
    staggered, each episode `select_action` on that env alone (to 1e-5)."""
    _, out = push_policies
    assert "together: max" in out and "staggered: max" in out and out.rstrip().endswith("OK")


def test_refilled_act_episodes_are_the_chunked_ones(push_c, push_policies, monkeypatch):
    """Through the server, ACT's chunks restart with each env's episode: refilled slots give
    every seed its chunked episode (outcomes exact; rewards to float rounding, since a
    chunk is predicted for fewer rows at a time)."""
    monkeypatch.setenv("OPENRAL_MJX_LEROBOT", "server")
    policy = make_policy(f"lerobot:{push_policies[0] / 'act'}", push_c)
    try:
        assert not policy.aligned_episodes
        kw = dict(seeds=np.arange(6), n_envs=3, max_steps=12)
        chunks, _ = run_seeds(push_c, policy, None, batching="chunks", **kw)
        refill, timing = run_seeds(push_c, policy, None, batching="refill", **kw)
    finally:
        policy.close()
    assert timing.batch_steps is not None  # the refill runner ran
    np.testing.assert_array_equal(refill["steps"], chunks["steps"])
    np.testing.assert_array_equal(refill["success"], chunks["success"])
    np.testing.assert_allclose(refill["total_reward"], chunks["total_reward"], rtol=1e-4)


def test_history_policies_run_in_aligned_chunks(push_c, push_policies, monkeypatch):
    """Diffusion keeps two observations for the whole batch: `auto` batching runs it in
    chunks, and asking for refill is a one-line error."""
    monkeypatch.setenv("OPENRAL_MJX_LEROBOT", "server")
    policy = make_policy(f"lerobot:{push_policies[0] / 'diffusion'}", push_c)
    try:
        assert policy.aligned_episodes
        assert resolve_batching("auto", "c", 100, 4, aligned=policy.aligned_episodes) == "chunks"
        with pytest.raises(ConfigError, match="use batching 'chunks'") as exc:
            run_seeds(
                push_c, policy, None, seeds=np.arange(4), n_envs=2, max_steps=3, batching="refill"
            )
        assert "\n" not in str(exc.value)
    finally:
        policy.close()


def test_unknown_lerobot_path_is_a_config_error(push_c, push_policies, monkeypatch):
    monkeypatch.setenv("OPENRAL_MJX_LEROBOT", "gpu")
    with pytest.raises(ConfigError, match="valid: process, server"):
        make_policy(f"lerobot:{push_policies[0] / 'act'}", push_c)
