"""JAX's persistent compilation cache, on by default for the CLIs, in a per-user directory."""

from __future__ import annotations

import os
from pathlib import Path

import jax


def default_cache_dir() -> Path:
    base = os.environ.get("XDG_CACHE_HOME") or str(Path.home() / ".cache")
    return Path(base) / "openral_mjx" / "jax"


def enable_compilation_cache(path: Path | None = None) -> Path:
    """Cache compiled XLA executables on disk so a repeated run skips most compilation.

    Executables that embed host callbacks (the `c` backend) are not cacheable; JAX skips them.
    """
    path = path or default_cache_dir()
    path.mkdir(parents=True, exist_ok=True)
    jax.config.update("jax_compilation_cache_dir", str(path))
    jax.config.update("jax_persistent_cache_min_compile_time_secs", 1.0)
    jax.config.update("jax_persistent_cache_min_entry_size_bytes", 0)
    return path
