"""JAX's persistent compilation cache, on by default for the CLIs, in a per-user directory,
and beside it the cache of traced episodes (`export_cache`)."""

from __future__ import annotations

import os
from pathlib import Path

import jax

_EXPORT_DIR: Path | None = None


def default_cache_dir() -> Path:
    base = os.environ.get("XDG_CACHE_HOME") or str(Path.home() / ".cache")
    return Path(base) / "openral_mjx" / "jax"


def enable_compilation_cache(path: Path | None = None) -> Path:
    """Cache compiled XLA executables on disk so a repeated run skips most compilation.

    Executables that embed host callbacks (the `c` backend) are not cacheable; JAX skips them.
    """
    global _EXPORT_DIR
    path = path or default_cache_dir()
    path.mkdir(parents=True, exist_ok=True)
    jax.config.update("jax_compilation_cache_dir", str(path))
    # every executable, sub-second ones too (the factor stages): a warm start compiles nothing
    jax.config.update("jax_persistent_cache_min_compile_time_secs", 0.0)
    jax.config.update("jax_persistent_cache_min_entry_size_bytes", 0)
    _EXPORT_DIR = path.parent / "export"
    return path


def export_dir() -> Path | None:
    """Where traced episodes are cached: beside the compilation cache, once it is enabled
    (a process-wide setting, like JAX's own cache directory)."""
    return _EXPORT_DIR
