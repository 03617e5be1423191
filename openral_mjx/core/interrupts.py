"""Ctrl-C and SIGTERM as one kind of stop: what signal ended a run, and its exit code.

Python turns SIGINT into `KeyboardInterrupt`; `signals_raise` makes SIGTERM raise `Terminated`
(a `KeyboardInterrupt` too) and records which signal arrived, so a run can keep what finished
whichever it was, and the CLI exits with the conventional 128 + signal number. A signal that
lands inside a host callback reaches the caller as a JAX error: `stop_signal` still names it
from the record while the handlers are installed, and JAX's log of that callback (its
traceback, on stderr) is dropped: the run says in one line that it stopped.
"""

from __future__ import annotations

import contextlib
import logging
import signal
from collections.abc import Iterator
from types import FrameType

_SEEN: list[str] = []  # signals received while `signals_raise` was active, in order
EXIT_CODES = {"SIGINT": 128 + signal.SIGINT, "SIGTERM": 128 + signal.SIGTERM}  # 130, 143
# JAX logs an exception raised in a host callback, with its traceback, before re-raising it
CALLBACK_LOGGER = "jax._src.callback"


class Terminated(KeyboardInterrupt):
    """SIGTERM arrived: stop as on Ctrl-C."""


def _raise(signum: int, frame: FrameType | None) -> None:
    name = signal.Signals(signum).name
    _SEEN.append(name)
    raise Terminated() if name == "SIGTERM" else KeyboardInterrupt()


def _not_a_stop(record: logging.LogRecord) -> bool:
    """False for a log record of an exception that is a stop (Ctrl-C, SIGTERM)."""
    return not (record.exc_info and isinstance(record.exc_info[1], KeyboardInterrupt))


@contextlib.contextmanager
def signals_raise() -> Iterator[None]:
    """Within: SIGINT raises `KeyboardInterrupt`, SIGTERM `Terminated`, each recorded for
    `stop_signal`, and JAX logs no traceback for a host callback they end; an exception that
    leaves the block after a signal leaves it as that stop. The previous handlers come back
    after (main thread only: elsewhere a no-op, since Python delivers signals to the main
    thread)."""
    try:
        previous = {s: signal.signal(s, _raise) for s in (signal.SIGINT, signal.SIGTERM)}
    except ValueError:  # not the main thread
        yield
        return
    _SEEN.clear()
    callbacks = logging.getLogger(CALLBACK_LOGGER)
    callbacks.addFilter(_not_a_stop)
    try:
        yield
    except Exception as e:  # e.g. a JAX error around a signal raised in a host callback
        if not _SEEN:
            raise
        raise (Terminated() if _SEEN[-1] == "SIGTERM" else KeyboardInterrupt()) from e
    finally:
        callbacks.removeFilter(_not_a_stop)
        for s, handler in previous.items():
            signal.signal(s, handler)
        _SEEN.clear()  # a later error outside is no stop


def stop_signal(exc: BaseException) -> str | None:
    """ "SIGINT" or "SIGTERM" if `exc` is (or follows) a stop by that signal, else None."""
    if isinstance(exc, Terminated):
        return "SIGTERM"
    if isinstance(exc, KeyboardInterrupt):
        return _SEEN[-1] if _SEEN else "SIGINT"
    return _SEEN[-1] if _SEEN else None


def stop_reason(signal_name: str) -> str:
    """The words a partial report and the CLI use for a stop by `signal_name`."""
    return f"{'terminated' if signal_name == 'SIGTERM' else 'interrupted'} ({signal_name})"
