"""Numpy-aware message framing between the evaluator and its worker processes.

A message is a JSON header followed by the raw bytes of every numpy array it holds, so it
reads the same under any numpy version on either side (worker environments pin older numpy
than the evaluator's) and nothing is unpickled. Frame: ``u32 header length | header | u64 body
length | body``; the header is the message with each array replaced by
``{"__nd__": index, "dtype": str, "shape": [...]}`` pointing into the body.

Standard library and numpy only: this module is imported inside worker environments.
"""

from __future__ import annotations

import io
import json
import struct
from collections.abc import Callable
from typing import Any, BinaryIO

import numpy as np

_HEAD = struct.Struct("<I")
_BODY = struct.Struct("<Q")


def _strip(obj: Any, buffers: list[np.ndarray]) -> Any:
    if isinstance(obj, np.ndarray | np.generic):
        arr = np.asarray(obj, order="C")  # (ascontiguousarray would make a 0-d array 1-d)
        if arr.dtype.hasobject:
            raise TypeError(f"cannot send an object array (dtype {arr.dtype})")
        buffers.append(arr)
        return {"__nd__": len(buffers) - 1, "dtype": arr.dtype.str, "shape": list(arr.shape)}
    if isinstance(obj, dict):
        return {str(k): _strip(v, buffers) for k, v in obj.items()}
    if isinstance(obj, list | tuple):
        return [_strip(v, buffers) for v in obj]
    if isinstance(obj, bool | int | float | str) or obj is None:
        return obj
    raise TypeError(f"cannot send a {type(obj).__name__}")


def encode(obj: Any) -> bytes:
    """One frame holding `obj`: dicts, lists, scalars, strings, None and numpy arrays."""
    buffers: list[np.ndarray] = []
    header = json.dumps(_strip(obj, buffers), separators=(",", ":")).encode()
    offsets, body_len = [], 0
    for arr in buffers:
        offsets.append(body_len)
        body_len += arr.nbytes
    meta = json.dumps(offsets).encode()
    head = _HEAD.pack(len(meta)) + meta + _HEAD.pack(len(header)) + header
    return b"".join([head, _BODY.pack(body_len), *(a.tobytes() for a in buffers)])


def _restore(obj: Any, body: memoryview, offsets: list[int]) -> Any:
    if isinstance(obj, dict):
        if "__nd__" in obj and set(obj) == {"__nd__", "dtype", "shape"}:
            dtype, shape = np.dtype(obj["dtype"]), tuple(obj["shape"])
            start = offsets[obj["__nd__"]]
            count = int(np.prod(shape, dtype=np.int64))
            arr = np.frombuffer(body, dtype=dtype, count=count, offset=start)
            return arr.reshape(shape).copy()
        return {k: _restore(v, body, offsets) for k, v in obj.items()}
    if isinstance(obj, list):
        return [_restore(v, body, offsets) for v in obj]
    return obj


def _read_exact(stream: BinaryIO, n: int) -> bytes:
    chunks, left = [], n
    while left:
        chunk = stream.read(left)
        if not chunk:
            raise EOFError("the other end closed the pipe")
        chunks.append(chunk)
        left -= len(chunk)
    return b"".join(chunks)


def parse_frame(read_exact: Callable[[int], bytes]) -> Any:
    """Read one frame written by `encode`, pulling bytes through `read_exact(n)` (which returns
    exactly n bytes or raises, e.g. EOFError at the end of the stream or on a deadline)."""
    (meta_len,) = _HEAD.unpack(read_exact(_HEAD.size))
    offsets = json.loads(read_exact(meta_len))
    (head_len,) = _HEAD.unpack(read_exact(_HEAD.size))
    header = json.loads(read_exact(head_len))
    (body_len,) = _BODY.unpack(read_exact(_BODY.size))
    body = memoryview(read_exact(body_len))
    return _restore(header, body, offsets)


def read_frame(stream: BinaryIO) -> Any:
    """Read one frame from a blocking binary stream (EOFError when it ends)."""
    return parse_frame(lambda n: _read_exact(stream, n))


def decode(frame: bytes) -> Any:
    """Inverse of `encode` for a whole frame in memory."""
    return read_frame(io.BytesIO(frame))


def write_frame(stream: BinaryIO, obj: Any) -> None:
    stream.write(encode(obj))
    stream.flush()
