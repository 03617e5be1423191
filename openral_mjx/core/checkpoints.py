"""Pytrees to and from orbax checkpoints, with user-facing errors.

Orbax refuses zero-size arrays, and a scene state holds some (an `mjx.Data` without actuator
activations, say), so a tree is saved as the dict of its non-empty leaves keyed by position,
and restored onto the structure of a template tree (concrete or `jax.eval_shape` output) that
supplies the empty leaves. A missing, unreadable or mismatched checkpoint is a `ConfigError`
naming the path.

`save_tree` returns the SHA-256 of every file it wrote, for the caller to keep in its own
metadata; `restore_tree` checks them before orbax reads anything. Damaged data then fails
with a clear message, before tensorstore's asynchronous readers start (an error among those
can leave stray tracebacks from background threads on stderr).
"""

from __future__ import annotations

import hashlib
import logging
from pathlib import Path
from typing import Any

import jax
import jax.numpy as jnp
import numpy as np
import orbax.checkpoint as ocp

from openral_mjx.core.errors import ConfigError

# Orbax logs every save and restore at INFO through absl; keep the CLIs' output ours.
logging.getLogger("absl").setLevel(logging.WARNING)


def _keyed(leaves: list[Any]) -> dict[str, Any]:
    return {f"{i:05d}": leaf for i, leaf in enumerate(leaves) if np.size(leaf) > 0}


def file_digests(path: Path) -> dict[str, str]:
    """SHA-256 of every file under directory `path`, keyed by relative path."""
    out = {}
    for p in sorted(Path(path).rglob("*")):
        if p.is_file():
            out[p.relative_to(path).as_posix()] = hashlib.sha256(p.read_bytes()).hexdigest()
    return out


def save_tree(path: Path, tree: Any) -> dict[str, str]:
    """Write `tree`'s arrays to the orbax checkpoint directory `path` (replacing it), blocking;
    return the files' digests.

    Orbax writes into a temporary directory and renames it when complete, so an interrupted
    save never leaves a half-written checkpoint at `path`.
    """
    path = Path(path).resolve()
    path.parent.mkdir(parents=True, exist_ok=True)
    ckpt = ocp.Checkpointer(ocp.StandardCheckpointHandler())
    try:
        ckpt.save(path, args=ocp.args.StandardSave(_keyed(jax.tree.leaves(tree))), force=True)
    finally:
        ckpt.close()
    return file_digests(path)


def restore_tree(
    path: Path, template: Any, what: str = "checkpoint", digests: dict[str, str] | None = None
) -> Any:
    """Read the checkpoint at `path` onto `template`'s structure, shapes and dtypes.

    Raises `ConfigError` if `path` is missing, its files differ from `digests` (when given),
    or it is unreadable or holds other shapes.
    """
    path = Path(path).resolve()
    if not path.is_dir():
        raise ConfigError(f"{what} {str(path)!r} does not exist")
    if digests is not None:
        found = file_digests(path)
        bad = sorted(k for k in digests if found.get(k) != digests[k])
        if bad:
            raise ConfigError(
                f"{what} {str(path)!r} is corrupt: {len(bad)}/{len(digests)} files missing or "
                f"changed (first: {bad[0]!r})"
            )
    leaves, treedef = jax.tree.flatten(template)
    abstract = _keyed([jax.ShapeDtypeStruct(np.shape(x), jnp.result_type(x)) for x in leaves])
    ckpt = ocp.Checkpointer(ocp.StandardCheckpointHandler())
    try:
        # Compare shapes from the metadata first: a mismatch found by the restore itself
        # leaves orbax's pending reads to print tracebacks from background threads.
        stored = {k: tuple(v.shape) for k, v in ckpt.metadata(path).item_metadata.tree.items()}
        wanted = {k: tuple(v.shape) for k, v in abstract.items()}
        if stored != wanted:
            diff = sorted(set(stored.items()) ^ set(wanted.items()))[0][0]
            raise ConfigError(
                f"{what} {str(path)!r} holds other arrays than expected (array {diff}: "
                f"{stored.get(diff, 'missing')} stored, {wanted.get(diff, 'none')} expected)"
            )
        restored = ckpt.restore(path, args=ocp.args.StandardRestore(abstract))
    except ConfigError:
        raise
    except Exception as e:  # orbax/tensorstore raise many types for damaged files
        detail = (str(e).strip().splitlines() or [type(e).__name__])[0][:200]
        raise ConfigError(f"{what} {str(path)!r} is corrupt or incompatible: {detail}") from None
    finally:
        ckpt.close()
    out = [
        restored.get(f"{i:05d}", jnp.zeros(np.shape(leaf), jnp.result_type(leaf)))
        for i, leaf in enumerate(leaves)
    ]
    return jax.tree.unflatten(treedef, out)
