"""Physics backends: how a batch of states advances (`mjx`, `warp` on JAX devices, `c` on CPU)."""

from __future__ import annotations

from collections.abc import Callable

import jax
import mujoco

from openral_mjx.core.errors import unknown
from openral_mjx.physics.base import (
    PhysicsBackend,
    PhysicsSettings,
    PhysicsState,
    Quantities,
    QuantitySpec,
)
from openral_mjx.physics.c_backend import CBackend
from openral_mjx.physics.mjx_backend import MjxBackend
from openral_mjx.physics.warp_backend import WarpBackend, warp_installed

BACKEND_NAMES = ("auto", "mjx", "warp", "c")


def resolve_backend_name(name: str) -> str:
    """Map `auto` to a concrete backend.

    `warp` where warp-lang and a CUDA GPU are present (3.5-5x MJX's JAX implementation on an
    H100), else `mjx` on any other accelerator, else `c`: MJX's JAX implementation on a CPU is
    ~100x slower per core than MuJoCo C, so a CPU-only machine gets the C engine.
    """
    if name not in BACKEND_NAMES:
        raise unknown("backend", name, BACKEND_NAMES)
    if name != "auto":
        return name
    platform = jax.default_backend()
    if platform == "gpu" and warp_installed():
        return "warp"
    return "c" if platform == "cpu" else "mjx"


def make_backend(
    name: str,
    spec: mujoco.MjSpec,
    quantities: QuantitySpec,
    n_substeps: int,
    settings: PhysicsSettings | None = None,
) -> PhysicsBackend:
    """Build the named backend (after resolving `auto`) for a composed scene spec."""
    resolved = resolve_backend_name(name)
    factories: dict[str, Callable[[], PhysicsBackend]] = {
        "mjx": lambda: MjxBackend(spec, quantities, n_substeps, settings),
        "warp": lambda: WarpBackend(spec, quantities, n_substeps, settings),
        "c": lambda: CBackend(spec, quantities, n_substeps, settings),
    }
    return factories[resolved]()


__all__ = [
    "BACKEND_NAMES",
    "CBackend",
    "MjxBackend",
    "PhysicsBackend",
    "PhysicsSettings",
    "PhysicsState",
    "Quantities",
    "QuantitySpec",
    "WarpBackend",
    "make_backend",
    "resolve_backend_name",
]
