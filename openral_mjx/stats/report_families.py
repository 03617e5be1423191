"""Families of reports compared at once: two suite reports task by task, or k reports of one
scene and task (`families` does the statistics; this module pairs the reports' episodes).

Every comparison here is paired by seed, so the reports must share seeds: per task for suites
(seed s of a task is one initial state in both runs), across all k reports for policies.
Episodes without a partner in every report are left out (and counted); a task or a report with
no common seed is a `ConfigError`, as are reports of other scenes or tasks (a mirror scene pairs
with its original, as in `compare_reports`).
"""

from __future__ import annotations

import dataclasses
from collections.abc import Sequence
from typing import Any

import numpy as np

from openral_mjx.core.errors import ConfigError
from openral_mjx.report import EvalReport
from openral_mjx.stats.families import ManyComparison, SuiteComparison, compare_many, compare_suites
from openral_mjx.stats.intervals import wilson_interval

SCHEMA = "openral_mjx.comparison/1"


def is_suite(report: EvalReport) -> bool:
    """Whether `report` is a suite run's (more than one per-task row)."""
    return len(report.per_task) > 1


def _seeds(seeds: Sequence[int]) -> str:
    s = sorted(seeds)
    return f"{s[0]}..{s[-1]}" if len(s) > 1 else str(s[0]) if s else "none"


def _by_task(report: EvalReport, label: str) -> dict[str, dict[int, bool]]:
    """Outcome per seed per task (episodes name their task; a one-task report's may not)."""
    out: dict[str, dict[int, bool]] = {}
    for e in report.episodes:
        task = str(e.metadata.get("task", report.task))
        seeds = out.setdefault(task, {})
        seed = int(e.metadata["seed"])
        if seed in seeds:
            raise ConfigError(
                f"report {label} has seed {seed} twice in task {task!r}; cannot pair its episodes"
            )
        seeds[seed] = bool(e.success)
    return out


def check_family(
    reports: Sequence[EvalReport], labels: Sequence[str], mirrored: Sequence[bool]
) -> None:
    """Raise `ConfigError` unless every report evaluates the first one's scene and task
    (`mirrored[i]`: report i's scene mirrors the first's, or the other way round)."""
    first, name = reports[0], labels[0]
    for r, label, mirror in zip(reports[1:], labels[1:], mirrored[1:], strict=True):
        for field in ("task",) if mirror else ("scene", "task"):
            v0, v = getattr(first, field), getattr(r, field)
            if v != v0:
                raise ConfigError(
                    f"reports are not comparable: {field} {v!r} ({label}) vs {v0!r} ({name})"
                )


@dataclasses.dataclass(frozen=True)
class SuiteReportComparison:
    """Two suite reports: `result` per task and for the suite mean; `left_out[task]` counts
    the episodes of (A, B) with no partner."""

    labels: tuple[str, str]
    result: SuiteComparison
    left_out: dict[str, tuple[int, int]]


def compare_suite_reports(
    a: EvalReport, b: EvalReport, labels: tuple[str, str], confidence: float = 0.95
) -> SuiteReportComparison:
    """Per-task paired comparisons (Holm over the tasks) and the stratified suite-mean
    difference, on each task's common seeds."""
    ta, tb = _by_task(a, labels[0]), _by_task(b, labels[1])
    if set(ta) != set(tb):
        only = sorted(set(ta) ^ set(tb))
        raise ConfigError(
            f"suite reports have different tasks: {', '.join(map(repr, only))} in one only; "
            f"{labels[0]} has {', '.join(sorted(ta))}; {labels[1]} has {', '.join(sorted(tb))}"
        )
    order = [r.task for r in a.per_task if r.task in ta] or sorted(ta)
    outcomes, left = {}, {}
    for task in order:
        sa, sb = ta[task], tb[task]
        common = sorted(set(sa) & set(sb))
        if not common:
            raise ConfigError(
                f"task {task!r} shares no seed: {labels[0]} ran seeds {_seeds(list(sa))}, "
                f"{labels[1]} ran {_seeds(list(sb))}; a paired comparison needs common seeds"
            )
        outcomes[task] = ([sa[s] for s in common], [sb[s] for s in common])
        left[task] = (len(sa) - len(common), len(sb) - len(common))
    return SuiteReportComparison(labels, compare_suites(outcomes, confidence), left)


@dataclasses.dataclass(frozen=True)
class ManyReportComparison:
    """k reports of one task on their common seeds (`n_seeds`); `left_out[i]` counts report
    i's episodes with no partner in every other report."""

    result: ManyComparison
    n_seeds: int
    left_out: tuple[int, ...]


def compare_many_reports(
    reports: Sequence[EvalReport], labels: Sequence[str], alpha: float = 0.05
) -> ManyReportComparison:
    """All pairwise paired comparisons of k reports (Holm) and the set not significantly worse
    than the best, on the seeds every report ran."""
    if len(set(labels)) != len(labels):
        raise ConfigError(f"report labels must differ, got {list(labels)}")
    for r, label in zip(reports, labels, strict=True):
        if is_suite(r):
            raise ConfigError(
                f"{label} is a suite report ({len(r.per_task)} tasks): compare suite reports two "
                "at a time, or k reports of one task"
            )
    seeds = [{int(e.metadata["seed"]): bool(e.success) for e in r.episodes} for r in reports]
    for r, s, label in zip(reports, seeds, labels, strict=True):
        if len(s) != len(r.episodes):
            raise ConfigError(f"report {label} has repeated seeds; cannot pair its episodes")
    common = sorted(set.intersection(*(set(s) for s in seeds)))
    if not common:
        for s, label in zip(seeds[1:], labels[1:], strict=True):
            if not set(s) & set(seeds[0]):
                raise ConfigError(
                    f"{label} shares no seed with {labels[0]} (seeds {_seeds(list(s))} vs "
                    f"{_seeds(list(seeds[0]))}): a paired comparison needs common seeds"
                )
        raise ConfigError(
            f"no seed is common to all {len(reports)} reports (seeds: "
            f"{', '.join(f'{x} {_seeds(list(s))}' for x, s in zip(labels, seeds, strict=True))})"
        )
    outcomes = {label: [s[x] for x in common] for label, s in zip(labels, seeds, strict=True)}
    left = tuple(len(s) - len(common) for s in seeds)
    return ManyReportComparison(compare_many(outcomes, alpha), len(common), left)


def _pct(x: float) -> str:
    return f"{100 * x:5.1f}%"


def _pts(x: float) -> str:
    return f"{100 * x:+6.1f}"


def _p(p: float) -> str:
    return "<1e-300" if p < 1e-300 else f"{p:.2g}"


def format_suite_comparison(sc: SuiteReportComparison) -> str:
    """Table per task (rates, B - A in points with its interval, McNemar p and Holm's), then
    the suite mean's line and the verdict."""
    r = sc.result
    level = round(100 * r.confidence)
    alpha = 1 - r.confidence
    width = max(len("task"), *(len(t) for t in r.tasks))
    lines = [
        f"A: {sc.labels[0]}",
        f"B: {sc.labels[1]}",
        f"{'task':{width}s}  {'seeds':>6s}  {'A':>6s}  {'B':>6s}  {'B - A':>6s}  "
        f"{f'{level}% CI':>16s}  {'p':>7s}  {'Holm p':>7s}",
    ]
    for task, c, adj in zip(r.tasks, r.per_task, r.adjusted, strict=True):
        mark = " *" if adj <= alpha else ""
        lines.append(
            f"{task:{width}s}  {c.n_a:6d}  {_pct(c.rate_a)}  {_pct(c.rate_b)}  "
            f"{_pts(c.difference)}  [{_pts(c.ci_low)}, {_pts(c.ci_high)}]  {_p(c.p_value):>7s}  "
            f"{_p(adj):>7s}{mark}"
        )
    lines.append(
        f"suite mean (tasks weighted equally): B - A = {100 * r.mean_difference:+.1f} points, "
        f"{level}% CI [{100 * r.ci_low:+.1f}, {100 * r.ci_high:+.1f}] (stratified over tasks)"
    )
    lines.append(
        f"per task: Newcombe paired interval, exact McNemar p, Holm-adjusted over {len(r.tasks)} "
        f"tasks (* = significant at the {100 * alpha:.3g}% family-wise level)"
    )
    left = {t: v for t, v in sc.left_out.items() if any(v)}
    if left:
        what = ", ".join(f"{t} {x} of A, {y} of B" for t, (x, y) in left.items())
        lines.append(f"note: episodes with no partner are left out: {what}")
    return "\n".join(lines)


def format_many_comparison(mc: ManyReportComparison) -> str:
    """Policies ranked by rate (Wilson interval), the pairwise table (B - A, interval, McNemar
    p, Holm's), and the set not significantly worse than the best."""
    r = mc.result
    level = round(100 * (1 - r.alpha))
    width = max(len("policy"), *(len(n) for n in r.names))
    lines = [f"{len(r.names)} policies on {mc.n_seeds:,} common seeds, ranked:"]
    n = mc.n_seeds
    for i in np.argsort([-x for x in r.rates], kind="stable"):
        name, rate = r.names[i], r.rates[i]
        low, high = wilson_interval(round(rate * n), n, 1 - r.alpha)
        tag = "best" if name == r.best else ("not worse" if name in r.not_worse else "worse")
        lines.append(f"  {name:{width}s}  {_pct(rate)} [{100 * low:.1f}, {100 * high:.1f}]  {tag}")
    lines.append(
        f"pairs (B - A; {level}% Newcombe paired interval per pair, exact McNemar p, "
        f"Holm-adjusted over {len(r.pairs)} pairs):"
    )
    pw = max(len(f"{b} - {a}") for a, b in r.pairs)
    for (a, b), c in r.pairs.items():
        adj = r.adjusted[(a, b)]
        mark = " *" if adj <= r.alpha else ""
        lines.append(
            f"  {f'{b} - {a}':{pw}s}  {_pts(c.difference)}  [{_pts(c.ci_low)}, "
            f"{_pts(c.ci_high)}]  p {_p(c.p_value):>7s}  Holm p {_p(adj):>7s}{mark}"
        )
    lines.append(
        f"not significantly worse than the best ({r.best}) at the {100 * r.alpha:.3g}% "
        f"family-wise level: {', '.join(r.not_worse)}"
    )
    if any(mc.left_out):
        lines.append(
            "note: episodes without a partner in every report are left out: "
            + ", ".join(f"{x} of {name}" for name, x in zip(r.names, mc.left_out, strict=True))
        )
    return "\n".join(lines)


def _comparison(c: Any) -> dict[str, Any]:
    return {k: (float(v) if isinstance(v, np.floating) else v) for k, v in vars(c).items()}


def suite_json(sc: SuiteReportComparison) -> dict[str, Any]:
    """The suite comparison as JSON-ready data (`SCHEMA`)."""
    r = sc.result
    return {
        "schema_version": SCHEMA,
        "kind": "suite",
        "a": sc.labels[0],
        "b": sc.labels[1],
        "confidence": r.confidence,
        "tasks": [
            {"task": t, **_comparison(c), "p_holm": adj, "left_out": list(sc.left_out[t])}
            for t, c, adj in zip(r.tasks, r.per_task, r.adjusted, strict=True)
        ],
        "mean_difference": r.mean_difference,
        "ci_low": r.ci_low,
        "ci_high": r.ci_high,
    }


def many_json(mc: ManyReportComparison) -> dict[str, Any]:
    """The k-policy comparison as JSON-ready data (`SCHEMA`)."""
    r = mc.result
    return {
        "schema_version": SCHEMA,
        "kind": "policies",
        "alpha": r.alpha,
        "n_seeds": mc.n_seeds,
        "policies": [
            {"name": n, "rate": rate, "left_out": x}
            for n, rate, x in zip(r.names, r.rates, mc.left_out, strict=True)
        ],
        "pairs": [
            {"a": a, "b": b, **_comparison(c), "p_holm": r.adjusted[(a, b)]}
            for (a, b), c in r.pairs.items()
        ],
        "best": r.best,
        "not_worse": list(r.not_worse),
    }


__all__ = [
    "SCHEMA",
    "ManyReportComparison",
    "SuiteReportComparison",
    "check_family",
    "compare_many_reports",
    "compare_suite_reports",
    "format_many_comparison",
    "format_suite_comparison",
    "is_suite",
    "many_json",
    "suite_json",
]
