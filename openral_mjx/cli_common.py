"""Shared CLI plumbing: one-line errors with exit code 2, reproducible command lines."""

from __future__ import annotations

import shlex
import sys
from collections.abc import Callable
from typing import NoReturn, TypeVar

from rich.console import Console

from openral_mjx.errors import ConfigError

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


def command_line(module: str, args: list[str]) -> str:
    return " ".join(["python", "-m", module, *(shlex.quote(a) for a in args)])
