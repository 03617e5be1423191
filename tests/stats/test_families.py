"""Families of comparisons: the suite-mean difference's stratified interval against simulated
suites (coverage, and its variance against the simulated spread), Holm's family-wise error
over tasks and over k policies under the global null, and the set not worse than the best."""

import numpy as np
import pytest

from openral_mjx.core.errors import ConfigError
from openral_mjx.stats import paired_comparison
from openral_mjx.stats.families import compare_many, compare_suites


def pairs(rng, n: int, p_a: float, p_b: float, psi: float) -> tuple[np.ndarray, np.ndarray]:
    """Paired outcomes on n seeds: only A with (psi - d) / 2, only B with (psi + d) / 2 of the
    seeds (d = p_b - p_a), both with p_a - (psi - d) / 2."""
    d = p_b - p_a
    only_a, only_b, both = (psi - d) / 2, (psi + d) / 2, p_a - (psi - d) / 2
    u = rng.random(n)
    a = (u < only_a) | ((u >= only_a + only_b) & (u < only_a + only_b + both))
    b = (u >= only_a) & (u < only_a + only_b + both)
    return a, b


TASKS = {"reach": (50, 0.9, 0.92, 0.06), "push": (200, 0.5, 0.6, 0.3), "pick": (120, 0.3, 0.3, 0.2)}


def test_per_task_rows_are_paired_comparisons_with_holm():
    rng = np.random.default_rng(0)
    data = {t: pairs(rng, n, pa, pb, psi) for t, (n, pa, pb, psi) in TASKS.items()}
    sc = compare_suites(data)
    for t, c in zip(sc.tasks, sc.per_task, strict=True):
        assert c == paired_comparison(*data[t])
    p = sorted((c.p_value, i) for i, c in enumerate(sc.per_task))
    m = len(p)
    # Holm by hand: running max of (m - rank) * p over the sorted p-values
    running = 0.0
    for rank, (value, i) in enumerate(p):
        running = max(running, min(1.0, (m - rank) * value))
        assert sc.adjusted[i] == pytest.approx(running)
    assert sc.mean_difference == pytest.approx(np.mean([c.difference for c in sc.per_task]))


def test_suite_mean_interval_covers_simulated():
    """2,000 simulated suites (tasks of 50, 200 and 120 seeds): the 95% stratified interval
    covers the true suite-mean difference within Monte-Carlo error (SE 0.5 points)."""
    rng = np.random.default_rng(1)
    truth = np.mean([pb - pa for _, pa, pb, _ in TASKS.values()])
    reps, covered, means = 2000, 0, []
    for _ in range(reps):
        sc = compare_suites({t: pairs(rng, *v) for t, v in TASKS.items()})
        covered += sc.ci_low <= truth <= sc.ci_high
        means.append(sc.mean_difference)
    assert abs(covered / reps - 0.95) < 3 * np.sqrt(0.95 * 0.05 / reps) + 0.005
    # the variance the interval uses is the spread of the estimate
    expected_sd = np.sqrt(
        sum((psi - (pb - pa) ** 2) / n for n, pa, pb, psi in TASKS.values())
    ) / len(TASKS)
    assert np.std(means) == pytest.approx(expected_sd, rel=0.06)


def test_holm_family_wise_error_over_k_policies():
    """Four policies with the same rate, correlated per seed: the chance that any pair is
    declared different stays <= alpha (1,000 runs: SE 0.7 points)."""
    rng = np.random.default_rng(2)
    reps, any_rejected = 1000, 0
    for _ in range(reps):
        hard = rng.random(300) < 0.4  # seeds hard for every policy
        outs = {
            f"p{i}": np.where(hard, rng.random(300) < 0.2, rng.random(300) < 0.9) for i in range(4)
        }
        mc = compare_many(outs)
        any_rejected += min(mc.adjusted.values()) <= 0.05
        assert set(mc.not_worse) >= {mc.best}
    assert any_rejected / reps <= 0.05 + 3 * np.sqrt(0.05 * 0.95 / reps)


def test_not_worse_than_best():
    rng = np.random.default_rng(3)
    outs = {
        "strong": rng.random(400) < 0.8,
        "same": rng.random(400) < 0.79,
        "weak": rng.random(400) < 0.3,
    }
    mc = compare_many(outs)
    assert mc.best in ("strong", "same") and set(mc.not_worse) == {"strong", "same"}
    assert mc.adjusted[("strong", "weak")] < 1e-10
    with pytest.raises(ConfigError, match="at least two"):
        compare_many({"one": outs["weak"]})
