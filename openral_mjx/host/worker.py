"""A worker process: builds one object from a factory and serves calls on it over pipes.

Started by `openral_mjx.host.pool` as ``python -m openral_mjx.host.worker`` with the worker
environment's interpreter. Requests arrive on stdin and replies leave on the original stdout,
framed by `openral_mjx.host.codec`; whatever the hosted code prints goes to stderr (the pool
sends that to a log file). Requests: ``{"op": "init", "factory": "module:callable", "kwargs":
{...}}``, ``{"op": "call", "method": name, "kwargs": {...}}`` and ``{"op": "close"}``; each
gets ``{"ok": true, "result": ...}`` or ``{"ok": false, "error": "Type: message",
"traceback": "..."}``.

The worker ignores Ctrl-C (the evaluator handles it and closes its workers), and exits when
its stdin closes or, on Linux, when its parent dies. Standard library and numpy only here.
"""

from __future__ import annotations

import ctypes
import importlib
import os
import signal
import sys
import traceback
from typing import Any

from openral_mjx.host.codec import read_frame, write_frame


def load(path: str) -> Any:
    """`module:attribute` -> the attribute."""
    module, _, attr = path.partition(":")
    if not attr:
        raise ValueError(f"factory {path!r} is not of the form module:callable")
    return getattr(importlib.import_module(module), attr)


def _die_with_parent() -> None:
    """Ask Linux to SIGTERM this process when its parent exits (no orphaned workers)."""
    try:
        libc = ctypes.CDLL(None, use_errno=True)
        libc.prctl(1, signal.SIGTERM)  # PR_SET_PDEATHSIG
    except (OSError, AttributeError):  # pragma: no cover - not Linux
        pass
    if os.getppid() == 1:  # the parent died before prctl took effect
        raise SystemExit(0)


def serve() -> None:
    replies = os.fdopen(os.dup(1), "wb")
    os.dup2(2, 1)  # prints of hosted code must not corrupt the protocol stream
    sys.stdout = sys.stderr
    signal.signal(signal.SIGINT, signal.SIG_IGN)
    _die_with_parent()
    requests = sys.stdin.buffer
    obj: Any = None
    while True:
        try:
            msg = read_frame(requests)
        except EOFError:
            break
        op = msg.get("op")
        try:
            if op == "init":
                obj = load(msg["factory"])(**msg.get("kwargs", {}))
                result = None
            elif op == "call":
                result = getattr(obj, msg["method"])(**msg.get("kwargs", {}))
            elif op == "close":
                write_frame(replies, {"ok": True, "result": None})
                break
            else:
                raise ValueError(f"unknown op {op!r}")
            reply = {"ok": True, "result": result}
        except Exception as e:
            reply = {
                "ok": False,
                "error": f"{type(e).__name__}: {e}",
                "traceback": traceback.format_exc(),
            }
        write_frame(replies, reply)
    close = getattr(obj, "close", None)
    if callable(close):
        close()


if __name__ == "__main__":
    serve()
