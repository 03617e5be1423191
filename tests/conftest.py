"""Shared fixtures: scenes are built once per session; compiled functions are reused."""

from __future__ import annotations

import os
from collections.abc import Iterator
from pathlib import Path

# LLVM's optimisation off for the tests' XLA code unless XLA_FLAGS names a level: compiles are
# most of the tests' time (the default tier runs ~20% faster), and under the package's CPU
# codegen pin (no FMA) the bits do not depend on the level (`tests/core/test_cpu_codegen.py`
# checks it). Tests that run MJX's physics compile it optimised (`xla_level`). Set before JAX
# starts its CPU backend; subprocesses inherit it.
from xla_level import FLAG as OPT_LEVEL
from xla_level import OPTIMISED

if OPT_LEVEL not in os.environ.get("XLA_FLAGS", ""):
    os.environ["XLA_FLAGS"] = f"{os.environ.get('XLA_FLAGS', '')} {OPT_LEVEL}=0".strip()

import jax
import pytest

from openral_mjx.physics import PhysicsSettings
from openral_mjx.scenes import So101Box, TabletopPush

# Reuse XLA compilations across test runs on this machine (CI starts cold either way).
jax.config.update("jax_compilation_cache_dir", str(Path(__file__).parent.parent / ".jax_cache"))
jax.config.update("jax_persistent_cache_min_compile_time_secs", 1.0)


@pytest.fixture
def xla_optimised() -> Iterator[None]:
    """Programs compiled through `jax.stages.Lowered.compile` (the runner's) at XLA's default
    optimisation level during the test (`xla_level`); its own patch, which a test's
    `monkeypatch.undo()` leaves in place."""
    compile_ = jax.stages.Lowered.compile

    def optimised(self, compiler_options=None, **kwargs):
        return compile_(self, {**OPTIMISED, **(compiler_options or {})}, **kwargs)

    with pytest.MonkeyPatch.context() as patch:
        patch.setattr(jax.stages.Lowered, "compile", optimised)
        yield


@pytest.fixture(scope="session")
def push_c() -> TabletopPush:
    return TabletopPush(backend="c", settings=PhysicsSettings(threads=2))


@pytest.fixture(scope="session")
def push_mjx() -> TabletopPush:
    return TabletopPush(backend="mjx")


@pytest.fixture(scope="session")
def push_warp() -> TabletopPush:
    """MuJoCo-Warp in its CPU mode (the kernels are built once per machine, then cached)."""
    return TabletopPush(backend="warp", settings=PhysicsSettings(batch_size=8))


@pytest.fixture(scope="session")
def box_c() -> So101Box:
    return So101Box(backend="c", settings=PhysicsSettings(threads=2))


@pytest.fixture(scope="session")
def scripted_eval(push_c):
    """8 seeds of the scripted expert, 100 steps (some succeed, some run out of time), with
    per-step rewards: shared by the video and plot tests."""
    from openral_mjx.evaluation import run_evaluation

    return run_evaluation(push_c, "scripted", n_envs=8, max_steps=100, step_rewards=True)


@pytest.fixture(scope="session")
def gl() -> str:
    """A working headless GL backend; CI must have one (`.ci/run` installs Mesa's EGL)."""
    from openral_mjx.physics.gl import GLUnavailable, gl_backend

    try:
        return gl_backend()
    except GLUnavailable as e:
        if os.environ.get("CI"):
            pytest.fail(f"CI must be able to render: {e}")
        pytest.skip(str(e))
