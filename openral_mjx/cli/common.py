"""Shared CLI plumbing: one-line errors with exit code 2, reproducible command lines."""

from __future__ import annotations

import shlex
import sys
from collections.abc import Callable
from typing import NoReturn, TypeVar

from rich.console import Console

from openral_mjx.core.errors import ConfigError
from openral_mjx.host.pool import INTERRUPTED

T = TypeVar("T")
stderr = Console(stderr=True, highlight=False)


def fail(message: str) -> NoReturn:
    """Print `error: message` on one line to stderr and exit with code 2."""
    print(f"error: {message}", file=sys.stderr)
    raise SystemExit(2)


def guarded(main: Callable[[], T]) -> T:
    """Run `main`, turning user mistakes (`ConfigError`) into a one-line error and exit 2."""
    try:
        return main()
    except ConfigError as e:
        fail(str(e))
    except KeyboardInterrupt:
        print("interrupted", file=sys.stderr)
        raise SystemExit(130) from None
    except Exception:
        if INTERRUPTED.is_set():  # Ctrl-C inside a host callback reaches us as a JAX error
            print("interrupted", file=sys.stderr)
            raise SystemExit(130) from None
        raise


def command_line(module: str, args: list[str]) -> str:
    return " ".join(["python", "-m", module, *(shlex.quote(a) for a in args)])
