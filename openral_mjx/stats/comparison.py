"""Two policies on the same scene: is B's success rate different from A's?

Paired (same seeds): the exact McNemar test on the discordant seeds and Newcombe's paired
square-and-add interval for rate_B - rate_A. Unpaired: a two-proportion z test or Fisher's exact
test, and Newcombe's hybrid-score interval. Functions broadcast over numpy arrays (the tests
compute level and coverage exactly over every outcome).

References: Newcombe (1998), Statist. Med. 17: 873-890 (unpaired) and 2635-2650 (paired);
Fagerland, Lydersen & Laake (2017), "Statistical Analysis of Contingency Tables", ch. 4 and 8.
"""

from __future__ import annotations

import dataclasses
from typing import Any

import numpy as np
from scipy import stats as sps

from openral_mjx.core.errors import ConfigError, unknown
from openral_mjx.stats.intervals import (
    check_binomial_counts,
    check_confidence,
    scalar_or_array,
    wilson_interval,
)

UNPAIRED_TESTS = ("auto", "two-proportion-z", "fisher-exact")


@dataclasses.dataclass(frozen=True)
class Comparison:
    """Policy B against policy A: the difference of success rates B - A, an interval for it,
    and the p-value of a test of equal rates.

    Paired comparisons (same seeds) carry the 2x2 table of outcomes per seed: `both`,
    `only_a`, `only_b` (the discordant pairs the McNemar test uses) and `neither`.
    """

    paired: bool
    test: str
    interval_method: str
    confidence: float
    n_a: int
    successes_a: int
    n_b: int
    successes_b: int
    difference: float
    ci_low: float
    ci_high: float
    p_value: float
    both: int | None = None
    only_a: int | None = None
    only_b: int | None = None
    neither: int | None = None

    @property
    def rate_a(self) -> float:
        return self.successes_a / self.n_a

    @property
    def rate_b(self) -> float:
        return self.successes_b / self.n_b


def mcnemar_exact_pvalue(only_a: Any, only_b: Any) -> Any:
    """Exact (conditional) McNemar test: two-sided binomial test of `only_b` out of the
    discordant pairs at 1/2. Its level is at most alpha for every n and discordance rate."""
    b, c = np.asarray(only_a), np.asarray(only_b)
    m = b + c
    p = np.minimum(1.0, 2 * sps.binom.cdf(np.minimum(b, c), m, 0.5))
    return scalar_or_array(np.where(m == 0, 1.0, p))


def newcombe_paired_interval(
    both: Any, only_a: Any, only_b: Any, neither: Any, confidence: float = 0.95
) -> tuple[Any, Any]:
    """Interval for the paired difference rate_b - rate_a: Newcombe's square-and-add of the two
    marginal Wilson intervals, with the correlation estimate phi corrected as in Fagerland,
    Lydersen & Laake (2017, ch. 8). Broadcasts over arrays."""
    a, c, b, d = (np.asarray(x, np.float64) for x in (both, only_a, only_b, neither))
    n = a + b + c + d
    # Group 1 = B (successes a + b), group 2 = A (successes a + c): delta = (b - c) / n.
    p1, p2 = (a + b) / n, (a + c) / n
    l1, u1 = (np.asarray(x) for x in wilson_interval(a + b, n, confidence))
    l2, u2 = (np.asarray(x) for x in wilson_interval(a + c, n, confidence))
    prod = (a + b) * (c + d) * (a + c) * (b + d)
    cross = a * d - b * c
    corrected = np.where(cross > n / 2, cross - n / 2, np.where(cross >= 0, 0.0, cross))
    with np.errstate(invalid="ignore", divide="ignore"):
        phi = np.where(prod > 0, corrected / np.sqrt(np.where(prod > 0, prod, 1.0)), 0.0)
    delta = p1 - p2
    low = delta - np.sqrt(
        np.maximum(0.0, (p1 - l1) ** 2 - 2 * phi * (p1 - l1) * (u2 - p2) + (u2 - p2) ** 2)
    )
    high = delta + np.sqrt(
        np.maximum(0.0, (u1 - p1) ** 2 - 2 * phi * (u1 - p1) * (p2 - l2) + (p2 - l2) ** 2)
    )
    return scalar_or_array(np.maximum(-1.0, low)), scalar_or_array(np.minimum(1.0, high))


def newcombe_interval(
    successes_a: Any, n_a: Any, successes_b: Any, n_b: Any, confidence: float = 0.95
) -> tuple[Any, Any]:
    """Interval for rate_b - rate_a from independent samples: Newcombe's hybrid score
    (square-and-add of the two Wilson intervals; his method 10). Broadcasts over arrays."""
    la, ua = (np.asarray(x) for x in wilson_interval(successes_a, n_a, confidence))
    lb, ub = (np.asarray(x) for x in wilson_interval(successes_b, n_b, confidence))
    pa = np.asarray(successes_a, np.float64) / np.asarray(n_a)
    pb = np.asarray(successes_b, np.float64) / np.asarray(n_b)
    delta = pb - pa
    low = delta - np.sqrt((pb - lb) ** 2 + (ua - pa) ** 2)
    high = delta + np.sqrt((ub - pb) ** 2 + (pa - la) ** 2)
    return scalar_or_array(low), scalar_or_array(high)


def two_proportion_z_pvalue(successes_a: Any, n_a: Any, successes_b: Any, n_b: Any) -> Any:
    """Two-sided pooled two-proportion z test (the score test); 1 when no variance."""
    ka, na, kb, nb = (np.asarray(x, np.float64) for x in (successes_a, n_a, successes_b, n_b))
    pooled = (ka + kb) / (na + nb)
    var = pooled * (1 - pooled) * (1 / na + 1 / nb)
    with np.errstate(invalid="ignore", divide="ignore"):
        z = (kb / nb - ka / na) / np.sqrt(np.where(var > 0, var, 1.0))
    return scalar_or_array(np.where(var > 0, 2 * sps.norm.sf(np.abs(z)), 1.0))


def _unpaired_test(ka: int, na: int, kb: int, nb: int, test: str) -> str:
    if test not in UNPAIRED_TESTS:
        raise unknown("unpaired test", test, UNPAIRED_TESTS)
    if test != "auto":
        return test
    # The z test's normal approximation wants every expected cell count >= 5 (Cochran).
    pooled = (ka + kb) / (na + nb)
    expected = min(n * r for n in (na, nb) for r in (pooled, 1 - pooled))
    return "two-proportion-z" if expected >= 5 else "fisher-exact"


def paired_comparison(success_a: Any, success_b: Any, confidence: float = 0.95) -> Comparison:
    """Compare per-seed outcomes on common seeds (element i of both arrays = the same seed):
    exact McNemar test, Newcombe paired interval for rate_b - rate_a."""
    a, b = np.asarray(success_a, bool), np.asarray(success_b, bool)
    if a.shape != b.shape or a.ndim != 1 or a.size == 0:
        raise ConfigError(
            f"paired outcomes need two equal, non-empty 1-D arrays, got {a.shape}, {b.shape}"
        )
    check_confidence(confidence)
    both, only_a = int((a & b).sum()), int((a & ~b).sum())
    only_b, neither = int((~a & b).sum()), int((~a & ~b).sum())
    low, high = newcombe_paired_interval(both, only_a, only_b, neither, confidence)
    n = a.size
    return Comparison(
        paired=True,
        test="mcnemar-exact",
        interval_method="newcombe-paired",
        confidence=confidence,
        n_a=n,
        successes_a=both + only_a,
        n_b=n,
        successes_b=both + only_b,
        difference=(only_b - only_a) / n,
        ci_low=low,
        ci_high=high,
        p_value=mcnemar_exact_pvalue(only_a, only_b),
        both=both,
        only_a=only_a,
        only_b=only_b,
        neither=neither,
    )


def unpaired_comparison(
    successes_a: int,
    n_a: int,
    successes_b: int,
    n_b: int,
    confidence: float = 0.95,
    test: str = "auto",
) -> Comparison:
    """Compare two independent samples: Newcombe hybrid-score interval for rate_b - rate_a and
    a two-proportion z test, or Fisher's exact test (`auto`: Fisher when an expected cell
    count is below 5, where the z test's normal approximation is poor)."""
    check_binomial_counts(successes_a, n_a)
    check_binomial_counts(successes_b, n_b)
    check_confidence(confidence)
    chosen = _unpaired_test(successes_a, n_a, successes_b, n_b, test)
    if chosen == "fisher-exact":
        table = [[successes_b, n_b - successes_b], [successes_a, n_a - successes_a]]
        p = float(sps.fisher_exact(table).pvalue)
    else:
        p = two_proportion_z_pvalue(successes_a, n_a, successes_b, n_b)
    low, high = newcombe_interval(successes_a, n_a, successes_b, n_b, confidence)
    return Comparison(
        paired=False,
        test=chosen,
        interval_method="newcombe",
        confidence=confidence,
        n_a=int(n_a),
        successes_a=int(successes_a),
        n_b=int(n_b),
        successes_b=int(successes_b),
        difference=successes_b / n_b - successes_a / n_a,
        ci_low=low,
        ci_high=high,
        p_value=p,
    )


def holm_adjusted(p_values: Any) -> np.ndarray:
    """Holm's step-down adjustment of `p_values` for their number of comparisons: reject where
    the adjusted value is <= alpha, and the family-wise error stays <= alpha under any
    dependence between the tests (Holm 1979, Scand. J. Statist. 6: 65-70)."""
    p = np.asarray(p_values, np.float64)
    if p.ndim != 1:
        raise ConfigError(f"p-values must be a 1-D array, got shape {p.shape}")
    m = p.size
    order = np.argsort(p, kind="stable")
    stepped = np.minimum(1.0, np.maximum.accumulate((m - np.arange(m)) * p[order]))
    out = np.empty(m)
    out[order] = stepped
    return out
