"""Two evaluation reports compared: paired on their common seeds, else as independent samples.

Seed s is the same initial state in both runs of a scene and task, so the two outcomes of a
shared seed are a matched pair (pairing removes the between-seed variation): exact McNemar
test and Newcombe's paired interval. Reports with no seed in common (or compared `unpaired`)
use a two-proportion z test or Fisher's exact test and Newcombe's hybrid-score interval.
Reports of another scene or task are not comparable (`ConfigError`), except a mirror scene's
and its original's (`mirrored`), whose seed s is the same initial state. Where both reports
succeed on a shared seed, the median difference in steps to success says whether one reaches
the goal sooner (a mirror whose successes come sooner is not quite the same task). Paired
reports also get the mean difference of two continuous values with a t interval
(`continuous`): steps to success where both succeed, total reward on every common seed.
"""

from __future__ import annotations

import dataclasses
from collections.abc import Collection, Mapping
from typing import Any

import numpy as np

from openral_mjx.core.errors import ConfigError, unknown
from openral_mjx.report import EvalReport
from openral_mjx.stats.comparison import (
    UNPAIRED_TESTS,
    Comparison,
    paired_comparison,
    unpaired_comparison,
)
from openral_mjx.stats.continuous import PairedMean, format_paired_mean, paired_mean_difference
from openral_mjx.stats.intervals import check_confidence


@dataclasses.dataclass(frozen=True)
class ReportComparison:
    """A `Comparison` of two reports, with how the episodes were matched and what to know."""

    comparison: Comparison
    common_seeds: int
    left_out_a: int
    left_out_b: int
    notes: tuple[str, ...]
    # over the shared seeds where both succeed: how many, and the median of B's steps to
    # success minus A's (None: no such seed)
    both_succeeded: int = 0
    steps_median_difference: float | None = None
    # paired reports: mean B - A with a t interval, of the steps to success (seeds where both
    # succeed) and of the total reward (every common seed); None where no seed qualifies
    steps_difference: PairedMean | None = None
    reward_difference: PairedMean | None = None


def check_comparable(
    a: EvalReport,
    b: EvalReport,
    mirrored: bool = False,
    seed_options: Mapping[str, Any] | None = None,
    seed_cycles: Collection[str] = (),
) -> int | None:
    """Raise `ConfigError` unless both reports evaluate the same scene and task (the scenes
    may differ where `mirrored`: one mirrors the other) and agree on `seed_options`, the
    options that choose which initial state a seed starts from (name -> the value a report
    that does not record it ran with), except those in `seed_cycles` (`check_seed_options`).
    Returns the seed below which their seeds pair (None: all)."""
    for field in ("task",) if mirrored else ("scene", "task"):
        va, vb = getattr(a, field), getattr(b, field)
        if va != vb:
            raise ConfigError(f"reports are not comparable: {field} {va!r} (A) vs {vb!r} (B)")
    return check_seed_options(a.options, b.options, seed_options or {}, cycles=seed_cycles)


def check_seed_options(
    a: Mapping[str, Any],
    b: Mapping[str, Any],
    seed_options: Mapping[str, Any],
    labels: tuple[str, str] = ("A", "B"),
    cycles: Collection[str] = (),
) -> int | None:
    """Raise `ConfigError` unless options `a` and `b` agree on each of `seed_options` (name ->
    the value a run that does not record it ran with): else their seeds start from different
    initial states. An option in `cycles` is a count of initial states that seed s takes
    ``s mod count`` of (LIBERO's ``sampled_states``): where two counts differ, seeds below
    both still start from the same states, and that bound is returned (None: every seed)."""
    bound = None
    for key, default in seed_options.items():
        va, vb = a.get(key, default), b.get(key, default)
        if va == vb:
            continue
        if key in cycles and isinstance(va, int) and isinstance(vb, int):
            bound = min(va, vb, *(() if bound is None else (bound,)))
            continue
        raise ConfigError(
            f"reports are not comparable: option {key} {va!r} ({labels[0]}) vs {vb!r} "
            f"({labels[1]}): their seeds start from different initial states"
        )
    return bound


def _outcomes(report: EvalReport, label: str) -> dict[int, bool]:
    out = {int(e.metadata["seed"]): bool(e.success) for e in report.episodes}
    if len(out) != len(report.episodes):
        raise ConfigError(f"report {label} has repeated seeds; cannot pair its episodes")
    return out


def _steps_to_success(report: EvalReport) -> dict[int, int]:
    return {
        int(e.metadata["seed"]): int(e.metadata.get("first_success_step", e.steps))
        for e in report.episodes
        if e.success
    }


def _rewards(report: EvalReport) -> dict[int, float]:
    return {int(e.metadata["seed"]): float(e.total_reward) for e in report.episodes}


def _notes(a: EvalReport, b: EvalReport) -> list[str]:
    notes = []
    differ = [f for f in ("robot", "backend", "max_steps") if getattr(a, f) != getattr(b, f)]
    # a mirror and its original are different scenes with different option sets: only the
    # options both have can differ in a way worth noting
    keys = sorted(
        set(a.options) & set(b.options) if a.scene != b.scene else set(a.options) | set(b.options)
    )
    options = [k for k in keys if a.options.get(k) != b.options.get(k) and k != "backend"]
    if differ or options:
        what = ", ".join(differ + [f"option {k}" for k in options])
        notes.append(f"the runs differ in {what}")
    for label, r in (("A", a), ("B", b)):
        if r.sequential is not None:
            notes.append(
                f"{label} stopped sequentially; the comparison treats its episodes as a fixed "
                "sample"
            )
    return notes


def compare_reports(
    a: EvalReport,
    b: EvalReport,
    confidence: float = 0.95,
    unpaired: bool = False,
    test: str = "auto",
    mirrored: bool = False,
    seed_options: Mapping[str, Any] | None = None,
    seed_cycles: Collection[str] = (),
) -> ReportComparison:
    """B against A: paired on common seeds when there are any (unless `unpaired`);
    `mirrored`: the reports' scenes differ, one mirroring the other; `seed_options`: the
    options both must agree on, but for counts of initial states in `seed_cycles`, where
    seeds below both counts pair (`check_comparable`)."""
    check_confidence(confidence)
    if test not in UNPAIRED_TESTS:
        raise unknown("unpaired test", test, UNPAIRED_TESTS)
    bound = check_comparable(a, b, mirrored, seed_options, seed_cycles)
    notes = _notes(a, b)
    if bound is not None:
        differ = [k for k in seed_cycles if a.options.get(k) != b.options.get(k)]
        notes.append(
            f"option {', '.join(differ)} differs: seeds below {bound} start from the same "
            "initial states on both, and only those pair"
        )
    if a.scene != b.scene:
        notes.append(
            f"scenes {a.scene} (A) and {b.scene} (B): one mirrors the other, seed s is the same "
            "initial state on both"
        )
    oa, ob = _outcomes(a, "A"), _outcomes(b, "B")
    common = sorted(s for s in set(oa) & set(ob) if bound is None or s < bound)
    sa, sb = _steps_to_success(a), _steps_to_success(b)
    both = [s for s in common if s in sa and s in sb]
    timing = {
        "both_succeeded": len(both),
        "steps_median_difference": float(np.median([sb[s] - sa[s] for s in both]))
        if both
        else None,
    }
    if common and not unpaired:
        comparison = paired_comparison(
            np.array([oa[s] for s in common]), np.array([ob[s] for s in common]), confidence
        )
        ra, rb = _rewards(a), _rewards(b)
        timing["steps_difference"] = paired_mean_difference(
            [sa[s] for s in both], [sb[s] for s in both], "steps to success", confidence
        )
        rewardless = [n for n, r in (("A", ra), ("B", rb)) if not any(r.values())]
        if a.scene != b.scene and rewardless:  # a mirror without the original's reward
            notes.append(
                f"no total reward compared: {' and '.join(rewardless)} collected 0 in every "
                "episode (a mirror task whose reward is not ported computes none)"
            )
        else:
            timing["reward_difference"] = paired_mean_difference(
                [ra[s] for s in common], [rb[s] for s in common], "total reward", confidence
            )
        left_a, left_b = len(oa) - len(common), len(ob) - len(common)
        if left_a or left_b:
            notes.append(
                f"{left_a} episodes of A and {left_b} of B have no partner and are left out "
                "(--unpaired uses them all, ignoring that shared seeds are correlated)"
            )
        return ReportComparison(comparison, len(common), left_a, left_b, tuple(notes), **timing)
    if common:
        notes.append(
            f"the reports share {len(common)} seeds: the unpaired test ignores their correlation"
        )
    comparison = unpaired_comparison(
        sum(oa.values()), len(oa), sum(ob.values()), len(ob), confidence, test
    )
    return ReportComparison(comparison, len(common), 0, 0, tuple(notes))


def _p(p: float) -> str:
    return "< 1e-300" if p < 1e-300 else f"= {p:.2g}"


def _points(x: float) -> str:
    return f"{100 * x:+.1f}"


def format_comparison(rc: ReportComparison, a: EvalReport, b: EvalReport, names=("A", "B")) -> str:
    """Human-readable lines: both rates, the matching, the difference, the verdict, notes."""
    c = rc.comparison
    lines = []
    for label, name, r in (("A", names[0], a), ("B", names[1], b)):
        lines.append(
            f"{label}: {name}  {r.scene}/{r.policy} on {r.backend}: {r.successes}/{r.n_episodes}"
            f" = {100 * r.success_rate:.1f}% [{100 * r.ci_low:.1f}, {100 * r.ci_high:.1f}]"
        )
    if c.paired:
        lines.append(
            f"paired on {rc.common_seeds:,} common seeds: both succeed {c.both}, only A "
            f"{c.only_a}, only B {c.only_b}, neither {c.neither}; per-seed agreement "
            f"{100 * (c.both + c.neither) / rc.common_seeds:.1f}%"
        )
        if rc.steps_median_difference is not None:
            seeds = "seed" if rc.both_succeeded == 1 else "seeds"
            line = (
                f"steps to success where both succeed ({rc.both_succeeded:,} {seeds}): median "
                f"B - A = {rc.steps_median_difference:+g}"
            )
            if (sd := rc.steps_difference) is not None and sd.ci_low is not None:
                line += (
                    f", mean {sd.mean:+.4g}, {round(100 * sd.confidence)}% t interval "
                    f"[{sd.ci_low:+.4g}, {sd.ci_high:+.4g}]"
                )
            lines.append(line)
        if rc.reward_difference is not None:
            lines.append(
                format_paired_mean(rc.reward_difference, f"over {rc.common_seeds:,} common seeds")
            )
        method, test = "Newcombe paired", "exact McNemar"
    else:
        lines.append(f"unpaired: {c.n_a:,} episodes of A, {c.n_b:,} of B")
        method = "Newcombe hybrid score"
        test = "Fisher's exact" if c.test == "fisher-exact" else "two-proportion z"
    level = round(100 * c.confidence)
    lines.append(
        f"B - A = {_points(c.difference)} points, {level}% CI [{_points(c.ci_low)}, "
        f"{_points(c.ci_high)}] ({method}); {test} p {_p(c.p_value)}"
    )
    alpha = 1 - c.confidence
    if c.p_value < alpha:
        direction = "higher" if c.difference > 0 else "lower"
        lines.append(f"B's success rate is {direction} than A's at the {100 * alpha:.3g}% level")
    else:
        lines.append(f"no difference detected at the {100 * alpha:.3g}% level")
    lines += [f"note: {n}" for n in rc.notes]
    return "\n".join(lines)
