"""Physics backends: how a batch of states advances (`mjx` on any JAX device, `c` on the CPU)."""

from __future__ import annotations

from collections.abc import Callable

import jax
import mujoco

from openral_mjx.errors import unknown
from openral_mjx.physics.base import PhysicsBackend, PhysicsState, Quantities, QuantitySpec
from openral_mjx.physics.c_backend import CBackend
from openral_mjx.physics.mjx_backend import MjxBackend

BACKEND_NAMES = ("auto", "mjx", "c")


def resolve_backend_name(name: str) -> str:
    """Map `auto` to a concrete backend: `mjx` where JAX has an accelerator, else `c`.

    MJX's JAX implementation on a CPU is ~100x slower per core than MuJoCo C, so a CPU-only
    machine gets the C engine.
    """
    if name not in BACKEND_NAMES:
        raise unknown("backend", name, BACKEND_NAMES)
    if name != "auto":
        return name
    return "c" if jax.default_backend() == "cpu" else "mjx"


def make_backend(
    name: str,
    spec: mujoco.MjSpec,
    quantities: QuantitySpec,
    n_substeps: int,
    *,
    threads: int | None = None,
) -> PhysicsBackend:
    """Build the named backend (after resolving `auto`) for a composed scene spec."""
    resolved = resolve_backend_name(name)
    factories: dict[str, Callable[[], PhysicsBackend]] = {
        "mjx": lambda: MjxBackend(spec, quantities, n_substeps),
        "c": lambda: CBackend(spec, quantities, n_substeps, threads=threads),
    }
    return factories[resolved]()


__all__ = [
    "BACKEND_NAMES",
    "CBackend",
    "MjxBackend",
    "PhysicsBackend",
    "PhysicsState",
    "Quantities",
    "QuantitySpec",
    "make_backend",
    "resolve_backend_name",
]
