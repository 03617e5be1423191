"""Shared CLI plumbing: one-line errors with exit code 2 (tyro's parse errors included),
numbers checked finite, reproducible command lines."""

from __future__ import annotations

import contextlib
import dataclasses
import io
import math
import re
import shlex
import sys
from collections.abc import Callable, Iterable
from typing import Any, NoReturn, TypeVar

from rich.console import Console

from openral_mjx.core.errors import ConfigError, RunFailed
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
    a stop by Ctrl-C or SIGTERM into one line and exit 130 or 143, and a run that failed
    (`RunFailed`) into one line and exit 1."""
    try:
        return main()
    except ConfigError as e:
        fail(str(e))
    except RunFailed as e:
        print(f"error: {e}", file=sys.stderr)
        raise SystemExit(1) from None
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


def parse(cli: Callable[[], T], prog: str) -> T:
    """Run `cli` (a `tyro.cli` call) and return its parsed arguments, checked by
    `check_numbers`. tyro reports a bad flag in a box of 5 to 9 lines; its text is caught and
    printed as one `error:` line naming the flag and the value (exit code 2). `--help` and
    anything else tyro prints pass through unchanged."""
    captured = io.StringIO()
    try:
        with contextlib.redirect_stderr(captured):
            args = cli()
    except SystemExit as e:
        if e.code not in (0, None):
            fail(one_line(captured.getvalue(), prog))
        sys.stderr.write(captured.getvalue())
        raise
    sys.stderr.write(captured.getvalue())
    guarded(lambda: check_numbers(args))
    return args


_ANSI = re.compile(r"\x1b\[[0-9;]*m")
_RULE = set("─━-╰╯┗┛ ")
# Python's conversion errors, said as what the flag expected and what it got
_PLAIN = (
    (re.compile(r"invalid literal for int\(\) with base 10: "), "expected an integer, got "),
    (re.compile(r"could not convert string to float: "), "expected a number, got "),
)


def one_line(text: str, prog: str) -> str:
    """tyro's boxed error as one line: the box's first paragraph (what is wrong, before the
    help text), with borders and wrapping removed, and where to find the help. tyro draws the
    box in UTF-8 (title in the top border) or, where stdout is not UTF-8, in ASCII (title on
    its own line, then a rule of dashes)."""
    text = _ANSI.sub("", text)
    paragraphs: list[list[str]] = [[]]
    for raw in text.splitlines():
        line = raw.strip().strip("│┃").strip()
        if line.startswith(("╭", "┏")) or (line and set(line) <= _RULE):
            paragraphs.append([])  # a border or a rule ends a paragraph
        elif line:
            paragraphs[-1].append(line)
    paragraphs = [p for p in paragraphs if p]
    if paragraphs and "╭" not in text and "┏" not in text and len(paragraphs) > 1:
        paragraphs = paragraphs[1:]  # the ASCII box's title
    message = " ".join(paragraphs[0]) if paragraphs else "invalid command line"
    for pattern, plain in _PLAIN:
        message = pattern.sub(plain, message)
    return f"{message} (see {prog} --help)"


def check_numbers(args: Any) -> None:
    """Every float flag of the parsed `args` dataclass (and every float of a tuple flag) is
    finite: tyro parses `nan` and `inf`, which no setting means and a JSON report cannot hold."""
    if not dataclasses.is_dataclass(args):
        return
    for field in dataclasses.fields(args):
        value = getattr(args, field.name)
        values = value if isinstance(value, tuple) else (value,)
        if any(isinstance(v, float) and not math.isfinite(v) for v in values):
            flag = "--" + field.name.replace("_", "-")
            shown = " ".join(map(str, values))
            raise ConfigError(f"{flag} must be a finite number, got {shown}")


def given_flags(pairs: Iterable[tuple[str, Any]]) -> list[str]:
    """``[flag, str(value), ...]`` for each `(flag, value)` whose value is not None: the
    options a run was given, for the command line that reproduces it."""
    return [item for flag, value in pairs if value is not None for item in (flag, str(value))]


def command_line(module: str, args: list[str]) -> str:
    return " ".join(["python", "-m", module, *(shlex.quote(a) for a in args)])
