"""Interrupted runs: the report of what finished, and picking up from it (`eval --resume`).

A sweep, a suite or a sequential run that a signal stops after some of its parts (points,
tasks, chunks of seeds) finished raises `Interrupted` carrying a report of those parts,
marked `partial` (`PartialInfo`). Given back as `resume`, that report's parts are not run
again: the rest run, and the result is the report an uninterrupted run gives (the same
episodes per seed; timings add up).
"""

from __future__ import annotations

import collections
from collections.abc import Iterable, Mapping

from openral_mjx.core.interrupts import stop_reason
from openral_mjx.report import EvalReport, PartialInfo
from openral_mjx.report.sweep import SweepReport


class Interrupted(KeyboardInterrupt):
    """A run stopped by `signal` ("SIGINT" or "SIGTERM") after some of it finished: `report`
    holds what did, marked partial."""

    def __init__(self, signal: str, report: EvalReport | SweepReport) -> None:
        super().__init__(stop_reason(signal))
        self.signal, self.report = signal, report


def partial_info(signal: str, unit: str, finished: list[str], total: int) -> PartialInfo:
    """`PartialInfo` for a stop by `signal` after the `finished` parts of `total`."""
    return PartialInfo(stop_reason(signal), unit, len(finished), total, finished)


def add_warnings(counts: Iterable[Mapping[str, int]]) -> dict[str, int]:
    """MuJoCo warning counts of several runs, added by kind."""
    total: collections.Counter[str] = collections.Counter()
    for c in counts:
        total.update(c)
    return dict(sorted(total.items()))


def add_seconds(parts: Iterable[Mapping[str, float]]) -> dict[str, float]:
    """Timings of several runs (e.g. their `build_s`), added by what they timed."""
    total: dict[str, float] = {}
    for part in parts:
        for what, seconds in part.items():
            total[what] = total.get(what, 0.0) + seconds
    return total
