"""XLA's LLVM optimisation level in the tests (conftest turns it off; see there and docs/tests.md).

MJX's JAX physics is the exception: unoptimised, XLA compiles it slower and runs it ~10x
slower (the float32 agreement test took 374 s at level 0 against 27 s), so the tests that run
it compile those programs with `OPTIMISED`: passed to `jax.jit` where a test jits directly, or
through the `xla_optimised` fixture for programs the runner compiles.
"""

from __future__ import annotations

from typing import Any

FLAG = "--xla_backend_optimization_level"
OPTIMISED: dict[str, Any] = {"xla_backend_optimization_level": 3}  # XLA's own default


def for_backend(backend: str) -> dict[str, Any] | None:
    """The compiler options for programs of `backend` in a test: optimised for `mjx` only."""
    return OPTIMISED if backend == "mjx" else None
