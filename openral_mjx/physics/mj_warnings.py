"""MuJoCo C's warnings, counted by kind instead of printed and logged.

By default MuJoCo prints the warnings it raises ("Nan, Inf or huge value in QACC ..."; the
first of each kind per `MjData` since its last reset, so a diverging batch stepped through
`rollout`'s per-thread data prints many) and appends each to `MUJOCO_LOG.TXT` in the current
directory. `count_warnings` installs a user warning handler (which replaces both) while it is
open and counts each message by its `mjtWarning` kind (`BADQACC`, `CONTACTFULL`, ...; `OTHER`
for a message of no kind): the counts are of the messages MuJoCo would have printed. Counters
nest: every open one counts every warning. MuJoCo calls the handler from its rollout threads
too, so counting takes a lock.
"""

from __future__ import annotations

import collections
import contextlib
import re
import threading
from collections.abc import Callable, Iterator

import mujoco

_LOCK = threading.Lock()
_OPEN: list[collections.Counter[str]] = []
_PREVIOUS: list[Callable[[str], None] | None] = []


def _prefixes() -> list[tuple[str, str]]:
    """(message prefix, kind) for every `mjtWarning`: its text up to the first number (the
    text carries the index of the offending DOF, contact or actuator)."""
    out = []
    for name, value in mujoco.mjtWarning.__members__.items():
        if name == "mjNWARNING":
            continue
        text = mujoco.mju_warningText(int(value), 0)
        out.append((re.split(r"\d", text, maxsplit=1)[0], name.removeprefix("mjWARN_")))
    return out


_KINDS = _prefixes()


def warning_kind(message: str) -> str:
    """The `mjtWarning` kind of a MuJoCo warning message without its prefix, e.g. "BADQACC"
    ("OTHER" if it is none of them)."""
    for prefix, kind in _KINDS:
        if message.startswith(prefix):
            return kind
    return "OTHER"


def _handler(message: str) -> None:
    kind = warning_kind(message)
    with _LOCK:
        for counts in _OPEN:
            counts[kind] += 1


@contextlib.contextmanager
def count_warnings() -> Iterator[collections.Counter[str]]:
    """Within: MuJoCo's warnings are counted (by kind, in the yielded counter), not printed
    and not written to `MUJOCO_LOG.TXT`; the previous handler comes back when the outermost
    counter closes."""
    counts: collections.Counter[str] = collections.Counter()
    with _LOCK:
        if not _OPEN:
            _PREVIOUS.append(mujoco.get_mju_user_warning())
            mujoco.set_mju_user_warning(_handler)
        _OPEN.append(counts)
    try:
        yield counts
    finally:
        with _LOCK:
            del _OPEN[next(i for i, c in enumerate(_OPEN) if c is counts)]  # not by ==
            if not _OPEN:
                mujoco.set_mju_user_warning(_PREVIOUS.pop())


def format_warnings(counts: dict[str, int]) -> str:
    """E.g. "BADQACC 12, CONTACTFULL 3" (largest first); "" for none."""
    ranked = sorted(counts.items(), key=lambda kv: (-kv[1], kv[0]))
    return ", ".join(f"{kind} {n:,}" for kind, n in ranked)
