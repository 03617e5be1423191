"""Worker processes seen from the evaluator: start, call with deadlines, detect crashes, clean up.

A `Worker` is one child process running `openral_mjx.host.worker` under some interpreter
(usually a managed worker environment's, see `openral_mjx.host.envs`). It imports only this
package's `host` modules, through a directory holding a link to the package, so none of the
evaluator's site-packages leak into the worker's environment. A worker that exits or does not
answer by its deadline raises `WorkerFailure` and is killed; every live worker is killed at
interpreter exit, on Ctrl-C and on exceptions (their owners close them in `finally` blocks).
"""

from __future__ import annotations

import atexit
import contextlib
import functools
import os
import select
import subprocess
import tempfile
import threading
import time
import weakref
from collections.abc import Callable, Sequence
from pathlib import Path
from typing import Any

from openral_mjx.host.codec import encode, parse_frame

_PACKAGE_DIR = Path(__file__).resolve().parent.parent
_LIVE: weakref.WeakSet[Worker] = weakref.WeakSet()
_SHIM: list[str] = []


INTERRUPTED = threading.Event()


def host_callback(fn: Callable[..., Any]) -> Callable[..., Any]:
    """Mark Ctrl-C seen inside a host callback: JAX reports any exception raised there as a
    failed callback, so the CLI checks `INTERRUPTED` to tell an interrupt from a bug."""

    @functools.wraps(fn)
    def wrapper(*args: Any, **kwargs: Any) -> Any:
        try:
            return fn(*args, **kwargs)
        except KeyboardInterrupt:
            INTERRUPTED.set()
            raise

    return wrapper


class WorkerFailure(RuntimeError):
    """A worker crashed, hung past its deadline, or could not start."""


class RemoteError(RuntimeError):
    """The hosted object raised; the message is the remote `Type: message`."""

    def __init__(self, message: str, traceback: str = "") -> None:
        super().__init__(message)
        self.remote_traceback = traceback


def _shim_dir() -> str:
    """A directory whose only entry links to this package (the worker's PYTHONPATH)."""
    if not _SHIM:
        d = tempfile.mkdtemp(prefix="openral_mjx_shim_")
        os.symlink(_PACKAGE_DIR, os.path.join(d, _PACKAGE_DIR.name))
        _SHIM.append(d)
    return _SHIM[0]


@atexit.register
def _kill_all() -> None:
    for worker in list(_LIVE):
        worker.kill()
    for d in _SHIM:
        with contextlib.suppress(OSError):
            os.unlink(os.path.join(d, _PACKAGE_DIR.name))
            os.rmdir(d)


class Worker:
    """One worker process hosting one object (see `openral_mjx.host.worker`).

    Args:
        python: interpreter of the worker's environment.
        env: extra environment variables (e.g. MUJOCO_GL).
        log_path: where the worker's stdout/stderr go.
        name: for messages.
        path_first: directories put before the worker's own packages on its import path (a
            package of this process to use there instead of the environment's own).
    """

    def __init__(
        self,
        python: str,
        env: dict[str, str] | None,
        log_path: Path,
        name: str = "worker",
        path_first: Sequence[str] = (),
    ) -> None:
        self.name = name
        self.log_path = log_path
        child_env = {
            k: v
            for k, v in os.environ.items()
            if k not in ("PYTHONPATH", "VIRTUAL_ENV", "PYTHONHOME")
        }
        child_env.update(env or {})
        child_env["PYTHONPATH"] = os.pathsep.join([*path_first, _shim_dir()])
        child_env["PYTHONUNBUFFERED"] = "1"
        # `python -m` would put the working directory (the temp dir) first on sys.path, where a
        # stray bisect.py once shadowed the standard library's; Python >= 3.11 leaves it out.
        child_env["PYTHONSAFEPATH"] = "1"
        log_path.parent.mkdir(parents=True, exist_ok=True)
        self._log = open(log_path, "ab")  # noqa: SIM115 - owned by the worker until kill()
        try:
            self.proc = subprocess.Popen(
                [python, "-m", "openral_mjx.host.worker"],
                stdin=subprocess.PIPE,
                stdout=subprocess.PIPE,
                stderr=self._log,
                env=child_env,
                cwd=tempfile.gettempdir(),
            )
        except OSError as e:
            self._log.close()
            raise WorkerFailure(f"{name}: could not start {python}: {e}") from None
        _LIVE.add(self)
        self._buf = b""

    @property
    def alive(self) -> bool:
        return self.proc.poll() is None

    def send(self, msg: dict[str, Any]) -> None:
        """Queue a request (the reply is read by `receive`)."""
        try:
            assert self.proc.stdin is not None
            self.proc.stdin.write(encode(msg))
            self.proc.stdin.flush()
        except (BrokenPipeError, OSError):
            raise self._failure("exited") from None

    def receive(self, timeout: float | None) -> Any:
        """The reply to the last request; `WorkerFailure` if the worker exits or does not
        answer within `timeout` seconds (it is killed then), `RemoteError` if it raised."""
        deadline = None if timeout is None else time.monotonic() + timeout
        assert self.proc.stdout is not None
        fd = self.proc.stdout.fileno()

        def read_exact(n: int) -> bytes:
            while len(self._buf) < n:
                left = None if deadline is None else deadline - time.monotonic()
                if left is not None and left <= 0:
                    raise self._failure(f"did not answer within {timeout:g} s", kill=True)
                ready, _, _ = select.select([fd], [], [], left)
                if not ready:
                    continue
                chunk = os.read(fd, max(n - len(self._buf), 1 << 16))
                if not chunk:
                    raise self._failure("exited")
                self._buf += chunk
            out, self._buf = self._buf[:n], self._buf[n:]
            return out

        reply = parse_frame(read_exact)
        if not reply["ok"]:
            raise RemoteError(reply["error"], reply.get("traceback", ""))
        return reply["result"]

    def call(self, msg: dict[str, Any], timeout: float | None) -> Any:
        self.send(msg)
        return self.receive(timeout)

    def _failure(self, what: str, kill: bool = False) -> WorkerFailure:
        if kill:
            self.kill()
        else:
            with contextlib.suppress(subprocess.TimeoutExpired):
                self.proc.wait(timeout=2)
        code = self.proc.poll()
        status = f" (exit code {code})" if code is not None and not kill else ""
        return WorkerFailure(f"{self.name} {what}{status}{self._log_tail()}")

    def _log_tail(self, lines: int = 3) -> str:
        try:
            tail = self.log_path.read_text(errors="replace").strip().splitlines()[-lines:]
        except OSError:
            return ""
        return f"; last log lines: {' | '.join(tail)}" if tail else ""

    def close(self, timeout: float = 5.0) -> None:
        """Ask the worker to finish, then make sure it has."""
        if self.alive:
            with contextlib.suppress(WorkerFailure, RemoteError, OSError, EOFError):
                self.call({"op": "close"}, timeout)
        self.kill()

    def kill(self) -> None:
        if self.alive:
            self.proc.kill()
        with contextlib.suppress(subprocess.TimeoutExpired):
            self.proc.wait(timeout=5)
        for stream in (self.proc.stdin, self.proc.stdout):
            with contextlib.suppress(OSError):
                if stream is not None:
                    stream.close()
        with contextlib.suppress(OSError):
            self._log.close()
        _LIVE.discard(self)
