"""Families of paired comparisons: two policies over a suite's tasks, and k policies on one task.

Suite: each task's paired difference rate_B - rate_A (exact McNemar p, Newcombe interval) with
Holm's correction over the tasks, and the suite-mean difference (tasks weighted equally, as a
suite report averages them) with a stratified Wald interval: the tasks' seeds are independent,
so its variance is the sum over tasks of var_t / T^2, each task's paired-difference variance
(p_only_a + p_only_b - delta_t^2) / n_t from its own sample size.

k policies on the same seeds: every pair's paired comparison with Holm's correction over the
k (k - 1) / 2 pairs (family-wise error <= alpha under any dependence), and the policies not
significantly worse than the best observed one.
"""

from __future__ import annotations

import dataclasses
from collections.abc import Mapping, Sequence

import numpy as np

from openral_mjx.core.errors import ConfigError
from openral_mjx.stats.comparison import Comparison, holm_adjusted, paired_comparison
from openral_mjx.stats.intervals import check_confidence, z_value


@dataclasses.dataclass(frozen=True)
class SuiteComparison:
    """Per task (`tasks`, `per_task`, Holm-adjusted p-values `adjusted`) and the suite-mean
    difference `mean_difference` with its stratified interval [`ci_low`, `ci_high`]."""

    tasks: tuple[str, ...]
    per_task: tuple[Comparison, ...]
    adjusted: tuple[float, ...]
    mean_difference: float
    ci_low: float
    ci_high: float
    confidence: float


def compare_suites(
    outcomes: Mapping[str, tuple[Sequence[bool], Sequence[bool]]], confidence: float = 0.95
) -> SuiteComparison:
    """`outcomes[task] = (A's outcomes, B's outcomes)` on that task's common seeds (element
    i of both: the same seed)."""
    check_confidence(confidence)
    if not outcomes:
        raise ConfigError("a suite comparison needs at least one task")
    tasks = tuple(outcomes)
    per_task = tuple(paired_comparison(*outcomes[t], confidence) for t in tasks)
    adjusted = tuple(float(p) for p in holm_adjusted([c.p_value for c in per_task]))
    diffs = np.array([c.difference for c in per_task])
    var = np.array(
        [
            ((c.only_a + c.only_b) / c.n_a - c.difference**2) / c.n_a  # type: ignore[operator]
            for c in per_task
        ]
    )
    mean = float(diffs.mean())
    half = z_value(confidence) * float(np.sqrt(var.sum())) / len(tasks)
    return SuiteComparison(
        tasks, per_task, adjusted, mean, max(-1.0, mean - half), min(1.0, mean + half), confidence
    )


@dataclasses.dataclass(frozen=True)
class ManyComparison:
    """k policies on common seeds: `pairs[(i, j)]` compares policy j (as B) with policy i (as
    A), `adjusted[(i, j)]` its Holm-adjusted p; `best` the highest observed rate and
    `not_worse` the policies not significantly worse than it at level `alpha`."""

    names: tuple[str, ...]
    rates: tuple[float, ...]
    pairs: dict[tuple[str, str], Comparison]
    adjusted: dict[tuple[str, str], float]
    best: str
    not_worse: tuple[str, ...]
    alpha: float


def compare_many(outcomes: Mapping[str, Sequence[bool]], alpha: float = 0.05) -> ManyComparison:
    """All pairwise paired comparisons of `outcomes[name]` (element i: seed i for every
    policy), Holm-corrected, and the set not significantly worse than the best."""
    if not 0 < alpha < 1:
        raise ConfigError(f"alpha must lie in (0, 1), got {alpha}")
    names = tuple(outcomes)
    if len(names) < 2:
        raise ConfigError(f"comparing policies needs at least two, got {len(names)}")
    arrays = {n: np.asarray(outcomes[n], bool) for n in names}
    pairs = {
        (a, b): paired_comparison(arrays[a], arrays[b], 1 - alpha)
        for i, a in enumerate(names)
        for b in names[i + 1 :]
    }
    keys = list(pairs)
    adjusted = dict(zip(keys, holm_adjusted([pairs[k].p_value for k in keys]), strict=True))
    rates = tuple(float(arrays[n].mean()) for n in names)
    best = names[int(np.argmax(rates))]

    def worse_than_best(name: str) -> bool:
        key = (name, best) if (name, best) in pairs else (best, name)
        diff = pairs[key].difference * (1 if key[1] == best else -1)  # best - name
        return bool(diff > 0 and adjusted[key] <= alpha)

    not_worse = tuple(n for n in names if n == best or not worse_than_best(n))
    return ManyComparison(
        names, rates, pairs, {k: float(v) for k, v in adjusted.items()}, best, not_worse, alpha
    )


__all__ = ["ManyComparison", "SuiteComparison", "compare_many", "compare_suites"]
