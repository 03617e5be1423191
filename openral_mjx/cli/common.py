"""Shared CLI plumbing: one-line errors with exit code 2, reproducible command lines."""

from __future__ import annotations

import shlex
import sys
from collections.abc import Callable
from typing import NoReturn, TypeVar

from rich.console import Console

from openral_mjx.core.errors import ConfigError
from openral_mjx.core.interrupts import EXIT_CODES, stop_reason, stop_signal
from openral_mjx.host.pool import INTERRUPTED

T = TypeVar("T")
stderr = Console(stderr=True, highlight=False)


def fail(message: str) -> NoReturn:
    """Print `error: message` on one line to stderr and exit with code 2."""
    print(f"error: {message}", file=sys.stderr)
    raise SystemExit(2)


def guarded(main: Callable[[], T]) -> T:
    """Run `main`, turning user mistakes (`ConfigError`) into a one-line error and exit 2, and
    a stop by Ctrl-C or SIGTERM into one line and exit 130 or 143."""
    try:
        return main()
    except ConfigError as e:
        fail(str(e))
    except KeyboardInterrupt as e:
        _stopped(stop_signal(e) or "SIGINT")
    except Exception as e:
        # a signal inside a host callback reaches us as a JAX error
        signal = stop_signal(e) or ("SIGINT" if INTERRUPTED.is_set() else None)
        if signal is None:
            raise
        _stopped(signal)


def _stopped(signal: str) -> NoReturn:
    print(stop_reason(signal), file=sys.stderr)
    raise SystemExit(EXIT_CODES[signal]) from None


def command_line(module: str, args: list[str]) -> str:
    return " ".join(["python", "-m", module, *(shlex.quote(a) for a in args)])
