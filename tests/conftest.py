"""Shared fixtures: scenes are built once per session; compiled functions are reused."""

from __future__ import annotations

from pathlib import Path

import jax
import pytest

from openral_mjx.physics import PhysicsSettings
from openral_mjx.scenes import So101Box, TabletopPush

# Reuse XLA compilations across test runs on this machine (CI starts cold either way).
jax.config.update("jax_compilation_cache_dir", str(Path(__file__).parent.parent / ".jax_cache"))
jax.config.update("jax_persistent_cache_min_compile_time_secs", 1.0)


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
