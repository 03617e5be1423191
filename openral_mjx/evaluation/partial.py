"""Interrupted runs: the report of what finished, and picking up from it (`eval --resume`).

A sweep, a suite or a sequential run that a signal stops after some of its parts (points,
tasks, chunks of seeds) finished raises `Interrupted` carrying a report of those parts,
marked `partial` (`PartialInfo`). Given back as `resume`, that report's parts are not run
again: the rest run, and the result is the report an uninterrupted run gives (the same
episodes per seed; timings add up).
"""

from __future__ import annotations

from collections.abc import Iterable, Mapping
from typing import TypeVar

from openral_mjx.core.interrupts import stop_reason
from openral_mjx.report import EvalReport, PartialInfo
from openral_mjx.report.sweep import SweepReport

N = TypeVar("N", int, float)


class Interrupted(KeyboardInterrupt):
    """A run stopped by `signal` ("SIGINT" or "SIGTERM") after some of it finished: `report`
    holds what did, marked partial."""

    def __init__(self, signal: str, report: EvalReport | SweepReport) -> None:
        super().__init__(stop_reason(signal))
        self.signal, self.report = signal, report


def partial_info(signal: str, unit: str, finished: list[str], total: int) -> PartialInfo:
    """`PartialInfo` for a stop by `signal` after the `finished` parts of `total`."""
    return PartialInfo(stop_reason(signal), unit, len(finished), total, finished)


def add_by_key(parts: Iterable[Mapping[str, N]]) -> dict[str, N]:
    """Several runs' per-key figures (MuJoCo's warning counts by kind, `build_s` seconds by
    what was built) added key by key, the keys sorted."""
    total: dict[str, N] = {}
    for part in parts:
        for key, value in part.items():
            total[key] = total[key] + value if key in total else value
    return dict(sorted(total.items()))
