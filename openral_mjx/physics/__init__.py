"""Physics backends: how a batch of states advances (`mjx`, `warp` on JAX devices, `c` on CPU).

`MjxBackend` and `WarpBackend` are imported when first used: importing `mujoco.mjx` pulls in
MuJoCo-Warp and defines its kernels (~7 s on a 2-core machine), which a run on `c`, a host
scene, a report or `--help` never needs.
"""

from __future__ import annotations

import importlib
from typing import TYPE_CHECKING, Any

import jax
import mujoco

from openral_mjx.core.errors import unknown
from openral_mjx.physics.base import (
    WARP_GRAPHS,
    PhysicsBackend,
    PhysicsSettings,
    PhysicsState,
    Quantities,
    QuantitySpec,
    release_warp_graphs,
    warp_installed,
)
from openral_mjx.physics.c_backend import CBackend

if TYPE_CHECKING:
    from openral_mjx.physics.mjx_backend import MjxBackend
    from openral_mjx.physics.warp_backend import WarpBackend

_LAZY = {"MjxBackend": "mjx_backend", "WarpBackend": "warp_backend"}
_CLASSES = {"mjx": "MjxBackend", "warp": "WarpBackend"}  # the lazily imported backends


def __getattr__(name: str) -> Any:
    """`MjxBackend` and `WarpBackend`, imported on first use (see the module docstring)."""
    if name in _LAZY:
        return getattr(importlib.import_module(f"{__name__}.{_LAZY[name]}"), name)
    raise AttributeError(f"module {__name__!r} has no attribute {name!r}")


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
    model: mujoco.MjModel | None = None,
) -> PhysicsBackend:
    """Build the named backend (after resolving `auto`) for a composed scene spec (`model`:
    the spec already compiled, see `PhysicsBackend`)."""
    resolved = resolve_backend_name(name)
    cls = CBackend if resolved == "c" else __getattr__(_CLASSES[resolved])
    return cls(spec, quantities, n_substeps, settings, model)


__all__ = [
    "BACKEND_NAMES",
    "WARP_GRAPHS",
    "CBackend",
    "MjxBackend",
    "PhysicsBackend",
    "PhysicsSettings",
    "PhysicsState",
    "Quantities",
    "QuantitySpec",
    "WarpBackend",
    "make_backend",
    "release_warp_graphs",
    "resolve_backend_name",
]
