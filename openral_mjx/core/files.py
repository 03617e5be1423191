"""Files that are never half-written: write beside the target, then `os.replace` over it."""

from __future__ import annotations

import contextlib
import json
import os
import tempfile
from collections.abc import Iterator
from pathlib import Path
from typing import Any

from openral_mjx.core.errors import ConfigError


def _umask() -> int:
    mask = os.umask(0)
    os.umask(mask)
    return mask


@contextlib.contextmanager
def atomic_path(path: Path) -> Iterator[Path]:
    """A temporary path beside `path` to write to; on success it replaces `path`, so `path`
    is never half-written (on failure the temporary file is removed). The file gets the
    permissions a plain `open(path, "w")` would (mkstemp's are 0600)."""
    path.parent.mkdir(parents=True, exist_ok=True)
    fd, tmp = tempfile.mkstemp(prefix=f".{path.name}.", suffix=".tmp", dir=path.parent)
    os.close(fd)
    try:
        yield Path(tmp)
        os.chmod(tmp, 0o666 & ~_umask())
        os.replace(tmp, path)
    except BaseException:
        Path(tmp).unlink(missing_ok=True)
        raise


def write_text_atomic(path: Path, text: str) -> None:
    """Write `text` to `path` via a temporary file and `os.replace`: never half-written."""
    with atomic_path(path) as tmp:
        tmp.write_text(text)


def write_json_atomic(path: Path, data: Any) -> None:
    """Write indented JSON to `path` atomically (NaN and infinity are errors)."""
    write_text_atomic(path, json.dumps(data, indent=1, allow_nan=False) + "\n")


def check_writable(path: Path, what: str = "--out") -> None:
    """Raise `ConfigError` unless a file can be written at `path`, checked before a long run so
    that its results are not lost to a bad path afterwards. The directory may not exist yet
    (it is made when the file is written); then its nearest existing ancestor must take a file.
    Probed by creating and deleting a temporary file there: permission bits alone do not tell
    (root, read-only mounts)."""
    if path.is_dir():
        raise ConfigError(f"{what} {str(path)!r} is a directory; give a file path")
    _probe(path, path.absolute().parent, what)


def check_writable_dir(path: Path, what: str = "--out") -> None:
    """Raise `ConfigError` unless files can be written in directory `path` (made if missing):
    `check_writable` for an output directory (a checkpoint, a training run)."""
    if path.exists() and not path.is_dir():
        raise ConfigError(f"{what} {str(path)!r} is a file; give a directory")
    _probe(path, path.absolute(), what)


def _probe(path: Path, parent: Path, what: str) -> None:
    """Create and delete a temporary file in `parent` or, where it does not exist yet, in its
    nearest existing ancestor; a `ConfigError` naming `path` if that fails."""
    while not parent.exists():
        parent = parent.parent
    if not parent.is_dir():
        raise ConfigError(f"{what} {str(path)!r}: {str(parent)!r} is not a directory")
    try:
        with tempfile.TemporaryFile(dir=parent):
            pass
    except OSError as e:
        raise ConfigError(
            f"{what} {str(path)!r}: cannot write in {str(parent)!r} ({e.strerror})"
        ) from None
