"""The CPU codegen pin: set where it should be, left alone where the user chose, and effective.

The effect is checked on XLA itself: ``a * x + b * x`` with ``a = -b`` is exactly 0 in IEEE
arithmetic, and XLA returns ~5e21 when it contracts one product into a fused multiply-add
(openxla/xla#41579). The layout invariance it buys on a real scene is checked on
`libero_mjx` (tests/benchmarks/libero/test_libero_mjx.py).
"""

from __future__ import annotations

import os
import platform
import re
import subprocess
import sys

import pytest

from openral_mjx.core.cpu_codegen import FLAG, OPT_OUT, pin_cpu_isa
from openral_mjx.report import load_report

X86 = platform.machine().lower() in ("x86_64", "amd64")
LEVEL = "--xla_backend_optimization_level"


def test_adds_the_flag_on_x86_beside_the_users_flags():
    env = {"XLA_FLAGS": "--xla_force_host_platform_device_count=2"}
    assert pin_cpu_isa(env, machine="x86_64")
    assert env["XLA_FLAGS"] == "--xla_force_host_platform_device_count=2 --xla_cpu_max_isa=AVX"
    env = {}
    assert pin_cpu_isa(env, machine="AMD64") and env["XLA_FLAGS"] == "--xla_cpu_max_isa=AVX"


@pytest.mark.parametrize(
    ("env", "machine", "pinned"),
    [
        ({"XLA_FLAGS": f"{FLAG}=AVX512"}, "x86_64", True),  # the user's own choice stays
        ({OPT_OUT: "native"}, "x86_64", False),
        ({}, "aarch64", False),  # the flag names x86 ISAs
    ],
)
def test_leaves_the_users_choice_and_other_machines_alone(env, machine, pinned):
    before = dict(env)
    assert pin_cpu_isa(env, machine=machine) is pinned
    assert env == before


def _fma_probe(extra_env: dict[str, str]) -> tuple[str, float]:
    """XLA_FLAGS after importing the package, and jit(a*x + b*x) for a = -b, in a fresh process."""
    code = (
        "import os, openral_mjx, jax, jax.numpy as jnp\n"
        "a = jnp.full((13,), 1e20, jnp.float32); x = jnp.full((13,), 1e10, jnp.float32)\n"
        "y = jax.jit(lambda a, b, x: a * x + b * x)(a, -a, x)\n"
        "print(os.environ.get('XLA_FLAGS', '')); print(float(abs(y).max()))\n"
    )
    env = {k: v for k, v in os.environ.items() if k not in ("XLA_FLAGS", OPT_OUT)}
    env |= {"JAX_PLATFORMS": "cpu", **extra_env}
    out = subprocess.run(
        [sys.executable, "-c", code], env=env, capture_output=True, text=True, check=True
    ).stdout.splitlines()
    return out[0], float(out[1])


@pytest.mark.skipif(not X86, reason="the pin applies to x86-64 only")
def test_importing_the_package_turns_fma_contraction_off():
    flags, value = _fma_probe({})
    assert flags == f"{FLAG}=AVX" and value == 0.0
    flags, value = _fma_probe({OPT_OUT: "native"})
    assert flags == ""
    if value == 0.0:  # a CPU without FMA: nothing to tell apart
        pytest.skip("this CPU has no FMA instructions")
    assert value > 1e20  # XLA's default contracts: what the pin prevents


def test_the_tests_optimisation_level_gives_the_users_bits(push_c, tmp_path):
    """The tests compile with LLVM's optimisation off (conftest); users get XLA's default.
    Under the pin, with no FMA to contract, the two must give the same episodes bit for bit,
    or the tests would check other numbers than users see: 16 seeds of the main job, here
    against a process at the other level."""
    from openral_mjx.evaluation import run_evaluation

    level = re.search(rf"{LEVEL}=(\d)", os.environ.get("XLA_FLAGS", ""))
    unoptimised = level is not None and level.group(1) == "0"
    other = "" if unoptimised else f"{LEVEL}=0"  # "": XLA's default, what users get
    ours = run_evaluation(push_c, "scripted", n_envs=16, max_steps=150).report.episodes
    out = tmp_path / "other_level.json"
    env = os.environ | {"JAX_PLATFORMS": "cpu", "XLA_FLAGS": other}
    argv = ["--n-envs", "16", "--max-steps", "150", "--backend", "c", "--out", str(out)]
    subprocess.run(
        [sys.executable, "-m", "openral_mjx.eval", *argv, "--no-breakdown"],
        env=env,
        check=True,
        capture_output=True,
    )
    theirs = load_report(out).episodes

    def key(e):
        return e.success, e.steps, e.total_reward, e.metadata["first_success_step"]

    assert [key(e) for e in ours] == [key(e) for e in theirs]
    assert 0 < sum(e.success for e in ours) < 16  # successes and failures both compared
