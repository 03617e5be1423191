"""The sweep report: success against one factor's value on the same seeds (``--sweep``).

One row per grid value (its rate and interval, and each seed's outcome, so any other paired
statistic can be computed later) and one row per pair of neighbouring values (the paired
difference, its interval, the exact McNemar p-value and its Holm adjustment over all pairs).
Written atomically as JSON, read back strictly.
"""

from __future__ import annotations

import dataclasses
import json
from functools import cache
from pathlib import Path
from typing import Any, ClassVar

from pydantic import ConfigDict, TypeAdapter

from openral_mjx.core.errors import ConfigError
from openral_mjx.core.files import write_text_atomic
from openral_mjx.report.io import check_readable
from openral_mjx.report.schema import ClusterInfo, PartialInfo
from openral_mjx.report.validation import STRICT, Count, Fraction, check, validate_data

SWEEP_SCHEMA_VERSION = "openral_mjx.sweep/4"
# /2 added `partial` (an interrupted sweep's finished points) and `mujoco_warnings`; a /1
# report reads with None and {}. /3 added `cluster` (where each point ran on a Ray cluster),
# None when read from /1 or /2. /4 added each point's `overflowed` (its diverged episodes whose
# engine buffers ran out, as the eval report's), 0 when read from /1-/3.
READABLE_SWEEP_VERSIONS = (
    "openral_mjx.sweep/1",
    "openral_mjx.sweep/2",
    "openral_mjx.sweep/3",
    SWEEP_SCHEMA_VERSION,
)


@dataclasses.dataclass
class SweepPoint:
    """One grid value: the run's rate, its 95% Wilson interval, its diverged episodes (and of
    them, `overflowed`: those whose engine buffers ran out), and per seed (in seed order) "1"
    for a success and "0" otherwise."""

    __pydantic_config__: ClassVar[ConfigDict] = STRICT

    value: float
    n_episodes: Count
    successes: Count
    success_rate: Fraction
    ci_low: Fraction
    ci_high: Fraction
    diverged: Count
    episodes_per_s: float
    outcomes: str
    overflowed: Count = 0


@dataclasses.dataclass
class SweepStep:
    """From one grid value to the next, on the same seeds: rate(to) - rate(from) with
    Newcombe's paired interval, the exact McNemar p-value, Holm-adjusted over every step,
    and whether the adjusted value is <= the sweep's alpha."""

    __pydantic_config__: ClassVar[ConfigDict] = STRICT

    from_value: float
    to_value: float
    difference: float
    ci_low: float
    ci_high: float
    p_value: Fraction
    p_adjusted: Fraction
    significant: bool


@dataclasses.dataclass
class SweepReport:
    """A sweep of `factor` (``NAME=LOW:HIGH:N`` as given; `relative`: multiples of the
    model's values) on seeds `seed .. seed + n_episodes - 1`, with `randomize` (the other
    factors, drawn per seed as in any randomised run) held the same at every point.
    `partial` (see `PartialInfo`): an interrupted sweep's report of its finished points, the
    first ones of the grid; `mujoco_warnings`: MuJoCo's warnings by kind over every point;
    `cluster`: None for a sweep run here, else where each point ran (`ClusterInfo`, its parts
    named by their values)."""

    __pydantic_config__: ClassVar[ConfigDict] = STRICT

    scene: str
    task: str
    policy: str
    backend: str
    device: str
    factor: str
    sweep: str
    relative: bool
    randomize: list[str]
    seed: Count
    n_episodes: Count
    alpha: Fraction
    correction: str
    points: list[SweepPoint]
    steps: list[SweepStep]
    compile_s: float
    run_s: float
    command: str
    created_at: str
    versions: dict[str, str]
    partial: PartialInfo | None = None
    mujoco_warnings: dict[str, int] = dataclasses.field(default_factory=dict)
    cluster: ClusterInfo | None = None
    schema_version: str = SWEEP_SCHEMA_VERSION

    def to_dict(self) -> dict[str, Any]:
        return dataclasses.asdict(self)

    @classmethod
    def from_dict(cls, data: Any) -> SweepReport:
        """Strict: another schema version, a wrong type, a missing or unknown field, or
        outcomes that do not match the counts is a `ConfigError` naming the field."""
        got = data.get("schema_version") if isinstance(data, dict) else None
        if got not in READABLE_SWEEP_VERSIONS:
            raise ConfigError(
                f"sweep schema {got!r} is not supported; valid: "
                f"{', '.join(READABLE_SWEEP_VERSIONS)}"
            )
        report = validate_data(_adapter(), data)
        for i, p in enumerate(report.points):
            where = f"points[{i}]"
            check(set(p.outcomes) <= {"0", "1"}, f"{where}.outcomes holds other than 0 and 1")
            check(len(p.outcomes) == p.n_episodes, f"{where}.outcomes is not n_episodes long")
            check(p.outcomes.count("1") == p.successes, f"{where}.successes != its outcomes")
            check(p.n_episodes == report.n_episodes, f"{where}.n_episodes != n_episodes")
            check(p.overflowed <= p.diverged, f"{where}.overflowed > its diverged")
        return report

    def summary(self) -> str:
        """The table the CLI prints: rate per value, then where success changes."""
        lines = [f"{self.scene}/{self.policy} on {self.backend}: sweep {self.sweep}"]
        if self.partial is not None:
            lines[0] += f" ({self.partial.summary()})"
        for p in self.points:
            lines.append(
                f"  {self.factor} = {p.value:<10g} success {100 * p.success_rate:5.1f}% "
                f"[{100 * p.ci_low:5.1f}, {100 * p.ci_high:5.1f}]  {p.successes}/{p.n_episodes}"
                + (f", {p.diverged} diverged" if p.diverged else "")
                + (f" ({p.overflowed} from full physics buffers)" if p.overflowed else "")
            )
        for s in self.steps:
            mark = "significant" if s.significant else "not significant"
            lines.append(
                f"  {s.from_value:g} -> {s.to_value:g}: {100 * s.difference:+.1f} points "
                f"[{100 * s.ci_low:+.1f}, {100 * s.ci_high:+.1f}], McNemar p={s.p_value:.3g}, "
                f"{self.correction} p={s.p_adjusted:.3g} ({mark} at {self.alpha:g})"
            )
        return "\n".join(lines)


def save_sweep(report: SweepReport, path: Path) -> None:
    write_text_atomic(path, json.dumps(report.to_dict(), indent=1, allow_nan=False) + "\n")


def load_sweep(path: Path) -> SweepReport:
    """Read a sweep report back; every problem is a `ConfigError` naming the file."""
    check_readable(path, "sweep report")
    try:
        return SweepReport.from_dict(json.loads(path.read_text()))
    except json.JSONDecodeError as e:
        raise ConfigError(f"sweep report {str(path)!r} is not valid JSON: {e}") from None
    except ConfigError as e:
        raise ConfigError(f"sweep report {str(path)!r}: {e}") from None


@cache
def _adapter() -> TypeAdapter[SweepReport]:
    return TypeAdapter(SweepReport)
