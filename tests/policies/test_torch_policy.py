"""`torch:MODULE:FACTORY`: a torch module in the evaluator's process, one callback per step.

References: a JAX policy computing the same copy of the observation (bit-identical episodes on
`c`), numpy for a linear layer, JAX's own buffer address for the zero-copy hand-off (inside
`jit`), and the chunked runner for continuous batching.
"""

from __future__ import annotations

import sys
from pathlib import Path

import jax
import jax.numpy as jnp
import numpy as np
import pytest

torch = pytest.importorskip("torch")

from openral_mjx import eval as eval_cli  # noqa: E402
from openral_mjx.core.errors import ConfigError  # noqa: E402
from openral_mjx.policies import Policy, make_policy  # noqa: E402
from openral_mjx.policies.torch_bridge import TorchBridge, bridge_policy  # noqa: E402
from openral_mjx.runner import run_seeds  # noqa: E402

FILE = Path(__file__).parents[1] / "data" / "torch_policies.py"


def spec(name: str) -> str:
    return f"torch:{FILE}:{name}"


def jax_tail(action_size: int) -> Policy:
    """The JAX twin of `torch_policies.tail`: the last `action_size` observation values."""

    def init(key, obs_spec):
        del key, obs_spec
        return None, None

    def act(params, pstate, obs, key):
        del params, key
        return obs[-action_size:], pstate

    return Policy("jax-tail", init, act)


def test_the_module_reads_jax_buffers_and_writes_actions_back():
    """The tensor the module gets is JAX's own buffer (same address, no copy), inside `jit`
    too, and the actions it returns are JAX's result, per env row."""
    seen = {}

    def run(inputs, steps):
        seen["ptr"], seen["steps"] = inputs["obs"].data_ptr(), steps.tolist()
        return inputs["obs"][:, :2] * 2

    bridge = TorchBridge(torch, run, {"obs": (4,)}, 2)
    policy = bridge_policy("double", bridge, lambda obs: {"obs": obs})
    obs = jnp.arange(12.0, dtype=jnp.float32).reshape(3, 4) + 1
    params, pstate = policy.init(jax.random.PRNGKey(0), None)
    pstate = jax.tree.map(lambda x: jnp.broadcast_to(x, (3, *x.shape)), pstate)
    act = jax.jit(jax.vmap(policy.act, in_axes=(None, 0, 0, None)))
    action, after = act(params, pstate, obs, jax.random.PRNGKey(0))
    assert seen["ptr"] == obs.unsafe_buffer_pointer()
    assert seen["steps"] == [0, 0, 0]
    np.testing.assert_array_equal(np.asarray(action), 2 * np.asarray(obs)[:, :2])
    np.testing.assert_array_equal(np.asarray(after["t"]), [1, 1, 1])


def test_torch_tail_equals_the_same_policy_in_jax(push_c):
    """Per-env copies of the observation through torch give the JAX policy's episodes bit for
    bit: every row reaches its own env, in both runners."""
    kw = dict(seeds=np.arange(6), n_envs=4, max_steps=12, record=("actions",))
    torch_tail = make_policy(spec("tail"), push_c)
    ref, _ = run_seeds(push_c, jax_tail(push_c.action_size), None, **kw)
    got, _ = run_seeds(push_c, torch_tail, None, **kw)
    for k in ("total_reward", "steps", "success", "actions"):
        np.testing.assert_array_equal(got[k], ref[k], err_msg=k)
    assert np.ptp(got["actions"][:, 0, 0]) > 0  # envs start in different states
    assert np.all(got["latency_max_ms"] > 0)  # the callback's time is the policy latency


def test_linear_layer_matches_numpy(push_c):
    policy = make_policy(spec("linear"), push_c)
    obs = jax.vmap(push_c.reset)(jax.random.split(jax.random.PRNGKey(3), 5)).obs
    params, pstate = policy.init(jax.random.PRNGKey(0), None)
    pstate = jax.tree.map(lambda x: jnp.broadcast_to(x, (5, *x.shape)), pstate)
    act = jax.jit(jax.vmap(policy.act, in_axes=(None, 0, 0, None)))
    action, _ = act(params, pstate, obs, jax.random.PRNGKey(0))
    g = torch.Generator().manual_seed(0)
    w = (0.01 * torch.randn(push_c.action_size, obs.shape[1], generator=g)).double().numpy()
    b = (0.1 * torch.randn(push_c.action_size, generator=g)).double().numpy()
    want = np.asarray(obs, np.float64) @ w.T + b
    np.testing.assert_allclose(np.asarray(action), want, rtol=1e-5, atol=1e-6)


def test_reset_per_episode_in_chunks_and_refill(push_c):
    """A module counting steps since its reset acts t * 1e-3 at step t of every episode, in
    every chunk; refilled slots get the same episodes as chunks (each reset when it starts)."""
    kw = dict(seeds=np.arange(8), n_envs=4, max_steps=10)
    chunks, _ = run_seeds(
        push_c, make_policy(spec("count_steps"), push_c), None, record=("actions",), **kw
    )
    steps = np.arange(10, dtype=np.float32) * 1e-3
    np.testing.assert_allclose(chunks["actions"][:, :, 0], np.tile(steps, (8, 1)), atol=1e-9)
    refill, timing = run_seeds(
        push_c, make_policy(spec("count_steps"), push_c), None, batching="refill", **kw
    )
    assert timing.batch_steps is not None  # the refill runner ran
    for k in ("total_reward", "steps", "success"):
        np.testing.assert_array_equal(refill[k], chunks[k], err_msg=k)


@pytest.mark.parametrize(
    "arg,needle",
    [
        ("torch", "policy 'torch' needs MODULE:FACTORY"),
        ("torch:nomodule", "needs MODULE:FACTORY"),
        ("torch:no_such_module_xyz:make", "torch policy module 'no_such_module_xyz' does not"),
        ("torch:missing.py:make", "torch policy file 'missing.py' does not exist"),
        (spec("nope"), "no callable 'nope'"),
        (spec("NOT_A_FACTORY"), "valid: CountSteps, Tail, count_steps, linear, tail"),
        (spec("wrong_size"), "returned 7 action values per env; scene 'tabletop_push' takes 6"),
    ],
)
def test_bad_specs_are_config_errors(push_c, arg, needle):
    with pytest.raises(ConfigError) as exc:
        make_policy(arg, push_c)
    assert needle in str(exc.value) and "\n" not in str(exc.value)


def test_without_torch_the_error_says_how_to_install(push_c, monkeypatch):
    monkeypatch.setitem(sys.modules, "torch", None)  # `import torch` raises ImportError
    with pytest.raises(ConfigError, match=r"pip install 'openral_mjx\[torch\]'"):
        make_policy(spec("tail"), push_c)


def test_eval_cli_runs_a_torch_policy(monkeypatch, capsys, tmp_path):
    out = tmp_path / "report.json"
    argv = ["--policy", spec("tail"), "--n-envs", "4", "--max-steps", "5", "--backend", "c"]
    monkeypatch.setattr(sys, "argv", ["openral_mjx.eval", *argv, "--out", str(out)])
    with pytest.raises(SystemExit) as exc:
        eval_cli.main()
    printed = capsys.readouterr().out
    assert exc.value.code == 0
    assert f"tabletop_push/torch:{FILE}:tail on c" in printed and out.is_file()
