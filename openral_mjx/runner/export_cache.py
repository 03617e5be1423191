"""Reuse a traced episode across processes: a serialized `jax.export` keyed by all it depends on.

JAX's persistent compilation cache skips XLA compilation on a repeated run, but not tracing and
lowering, which for MJX's JAX implementation is most of a warm start (several seconds: Python
walks the whole physics pipeline). Here the lowered program itself is stored, under a digest of
everything that decides it: this package's source, the versions of JAX, MuJoCo and friends,
JAX's numeric flags, the compiled scene model, the scene's options, the physics backend's
settings, the policy, the episode length, the per-device batch, the devices and the argument
shapes. A warm run deserializes it instead of tracing (and then hits the compilation cache).
Anything that cannot take part (host callbacks, policies without a `cache_key`) just lowers as
usual; a corrupt entry is rebuilt.
"""

from __future__ import annotations

import functools
import hashlib
import importlib.metadata
import json
import os
from collections.abc import Callable
from pathlib import Path
from typing import Any

import jax
import mujoco
import numpy as np
from jax import export

_PACKAGES = ("jax", "jaxlib", "mujoco", "mujoco-mjx", "flax", "numpy")


@functools.cache
def source_digest() -> str:
    """SHA-256 over every Python file of this package (paths and contents)."""
    root = Path(__file__).resolve().parent.parent  # the openral_mjx package
    h = hashlib.sha256()
    for path in sorted(root.rglob("*.py")):
        h.update(str(path.relative_to(root)).encode())
        h.update(path.read_bytes())
    return h.hexdigest()


def _version(name: str) -> str:
    try:
        return importlib.metadata.version(name)
    except importlib.metadata.PackageNotFoundError:
        return "none"


def model_digest(model: mujoco.MjModel) -> str:
    """SHA-256 of the compiled model's binary form."""
    buffer = np.zeros(mujoco.mj_sizeModel(model), np.uint8)
    mujoco.mj_saveModel(model, None, buffer)
    return hashlib.sha256(buffer.tobytes()).hexdigest()


def cache_key(**parts: Any) -> str:
    """Digest of `parts` (JSON-able, or `repr`-able) plus the source and package versions."""
    env = {
        "source": source_digest(),
        "versions": {name: _version(name) for name in _PACKAGES},
        "x64": bool(jax.config.jax_enable_x64),
        "matmul_precision": str(jax.config.jax_default_matmul_precision),
    }
    blob = json.dumps({"env": env, **parts}, sort_keys=True, default=repr)
    return hashlib.sha256(blob.encode()).hexdigest()


def argument_signature(args: Any) -> list[Any]:
    """Shapes, dtypes and tree structure of the arguments a program is lowered for."""
    leaves, tree = jax.tree.flatten(args)
    return [str(tree), [(tuple(np.shape(x)), str(np.asarray(x).dtype)) for x in leaves]]


def lower(fn: Callable, args: tuple, key: str | None, directory: Path | None) -> Any:
    """`fn.lower(*args)`, through a serialized export under `directory/key` when both are set.

    The same (exported) program is lowered whether the entry was just written or read, so the
    compilation cache sees one program across runs.
    """
    if key is None or directory is None:
        return fn.lower(*args)
    path = directory / f"{key}.jaxexport"
    exported = None
    if path.is_file():
        try:
            exported = export.deserialize(bytearray(path.read_bytes()))
        except Exception:  # corrupt or from an incompatible JAX: rebuild it
            exported = None
    if exported is None:
        try:
            exported = export.export(fn)(*args)
            blob = exported.serialize()
        except Exception:  # something in the program cannot be serialized: no caching
            return fn.lower(*args)
        directory.mkdir(parents=True, exist_ok=True)
        tmp = path.with_suffix(f".tmp{os.getpid()}-{id(exported)}")  # one per process
        tmp.write_bytes(blob)
        tmp.replace(path)
    return jax.jit(exported.call).lower(*args)
