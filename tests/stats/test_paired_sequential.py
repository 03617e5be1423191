"""The sequential paired comparison: its boundaries against the exact binomial test and
Clopper-Pearson (one look), its type-I error and power computed exactly over every path of
discordant counts, its repeated intervals against their definition, and its decisions and
interval coverage against simulated paired outcomes (stated Monte-Carlo error)."""

import itertools

import numpy as np
import pytest
from scipy import stats as sps

from openral_mjx.core.errors import ConfigError
from openral_mjx.stats import PairedDesign, clopper_pearson_interval, mcnemar_power
from openral_mjx.stats.paired_sequential import (
    PairedDecisionDesign,
    add_binomial,
    boundaries,
    crossing,
    repeated_interval,
    spent,
)


def d_paths(design: PairedDecisionDesign, psi: float):
    """Every path of cumulative discordant counts over the design's looks, with its
    probability when each seed is discordant with probability `psi`."""
    sizes = np.diff((0, *design.looks))
    for incs in itertools.product(*(range(s + 1) for s in sizes)):
        prob = float(np.prod([sps.binom.pmf(i, s, psi) for i, s in zip(incs, sizes, strict=True)]))
        yield tuple(int(x) for x in np.cumsum(incs)), prob


def exact_rejections(design: PairedDecisionDesign, psi: float, q: float) -> tuple[float, float]:
    """P(worse), P(better) by the test of no difference, exactly: over every path of
    discordant counts, the conditional crossing probabilities of B's count at `q`."""
    worse = better = 0.0
    for path, prob in d_paths(design, psi):
        bounds = boundaries(path, 0.5, design.budgets(design.alpha_q, len(path) - 1))
        low, high = crossing(path, bounds, q)
        worse, better = worse + prob * low, better + prob * high
    return worse, better


def test_add_binomial_is_the_binomial_convolution():
    """Binomial(3, p) plus 4 more trials is Binomial(7, p); a sub-stochastic mass (a crossed
    tail taken out) is carried as it is; no trials is a copy."""
    p = 0.3
    first = sps.binom.pmf(np.arange(4), 3, p)
    np.testing.assert_allclose(add_binomial(first, 4, p), sps.binom.pmf(np.arange(8), 7, p))
    cut = first.copy()
    cut[3] = 0.0
    expected = (
        sps.binom.pmf(np.arange(8), 7, p)
        - first[3] * np.r_[np.zeros(3), sps.binom.pmf(np.arange(5), 4, p)]
    )
    np.testing.assert_allclose(add_binomial(cut, 4, p), expected, atol=1e-15)
    same = add_binomial(first, 0, p)
    assert same is not first and np.array_equal(same, first)


def test_spending_functions():
    for kind in ("obrien-fleming", "pocock"):
        values = [spent(t, 0.05, kind) for t in np.linspace(0, 1, 21)]
        assert values[0] == 0 and values[-1] == 0.05
        assert np.all(np.diff(values) > 0)
    # O'Brien-Fleming spends far less early than Pocock
    assert spent(0.25, 0.05, "obrien-fleming") < 0.1 * spent(0.25, 0.05, "pocock")
    with pytest.raises(ConfigError, match="unknown spending function 'x'; valid: obrien"):
        spent(0.5, 0.05, "x")


def test_one_look_is_the_exact_binomial_test_and_clopper_pearson():
    design = PairedDecisionDesign((40,), alpha=0.05)
    for d in (1, 7, 25, 40):
        lower, upper = boundaries((d,), 0.5, design.budgets(design.alpha_q, 0))[0]
        tail = design.alpha_q / 2
        assert sps.binom.sf(upper - 1, d, 0.5) <= tail < sps.binom.sf(upper - 2, d, 0.5)
        assert sps.binom.cdf(lower, d, 0.5) <= tail < sps.binom.cdf(lower + 1, d, 0.5)
    for k in (0, 3, 20, 39, 40):
        got = repeated_interval((40,), k, (0.025,))
        assert got == pytest.approx(clopper_pearson_interval(k, 40, 0.95), abs=1e-8)


@pytest.mark.parametrize("spending", ["obrien-fleming", "pocock"])
def test_type_one_error_exact_over_every_path(spending):
    """Given any path of discordant counts the test of no difference crosses with
    probability <= alpha_q, so for every discordance; the bound is nearly attained."""
    design = PairedDecisionDesign.in_chunks(7, 21, alpha=0.05, spending=spending)
    worst = 0.0
    for path, _ in d_paths(design, 0.5):
        bounds = boundaries(path, 0.5, design.budgets(design.alpha_q, 2))
        worst = max(worst, sum(crossing(path, bounds, 0.5)))
    assert worst <= design.alpha_q + 1e-12
    for psi in (0.05, 0.3, 1.0):
        assert sum(exact_rejections(design, psi, 0.5)) <= design.alpha_q + 1e-12
    # larger designs: a discrete test's size; checked along simulated paths
    big = PairedDecisionDesign.in_chunks(100, 1000, spending=spending)
    rng = np.random.default_rng(1)
    sizes = []
    for _ in range(50):
        path = tuple(np.cumsum(rng.binomial(100, rng.uniform(0.02, 1), size=10)))
        bounds = boundaries(path, 0.5, big.budgets(big.alpha_q, 9))
        sizes.append(sum(crossing(path, bounds, 0.5)))
    assert max(sizes) <= big.alpha_q + 1e-12 and np.mean(sizes) > 0.8 * big.alpha_q


def test_power_exact_against_simulation():
    """Power at a stated effect (only A on 5%, only B on 35% of seeds: +30 points), exactly
    over every discordant path, against simulated paired outcomes run through the rule, and
    against the fixed-size exact McNemar test at the cap (the price of looking early)."""
    design = PairedDecisionDesign.in_chunks(8, 24, alpha=0.05)
    p_a, p_b = 0.05, 0.35
    worse, better = exact_rejections(design, p_a + p_b, p_b / (p_a + p_b))
    rng = np.random.default_rng(7)
    reps, wins = 200, 0
    for _ in range(reps):
        u = rng.random(design.cap)
        a, b = u < p_a, (u >= p_a) & (u < p_a + p_b)  # concordant seeds: both fail
        wins += design.run(a, b)[-1].decision == "better"
    se = np.sqrt(better * (1 - better) / reps)
    assert abs(wins / reps - better) < 4 * se, (wins / reps, better, se)
    fixed = mcnemar_power(design.cap, PairedDesign(0.5, p_b - p_a, p_a + p_b, design.alpha_q))
    # within a few points of it (discreteness can even put it a little above)
    assert worse < 1e-3 and better > 0.3 and abs(better - fixed) < 0.05, (better, fixed)


def test_repeated_interval_is_the_set_of_unrejected_rates():
    """Its endpoints are where the observed count starts and stops crossing that rate's own
    boundaries, and its coverage over every look at once is exact >= 1 - level."""
    rng = np.random.default_rng(3)
    for _ in range(10):
        trials = tuple(int(x) for x in np.cumsum(rng.integers(1, 30, size=4)))
        budgets = tuple(spent(t, 0.1, "pocock") / 2 for t in np.arange(1, 5) / 4)
        count = int(rng.integers(1, trials[-1]))
        low, high = repeated_interval(trials, count, budgets)
        for p, inside in (
            (low - 1e-6, False),
            (low + 1e-6, True),
            (high - 1e-6, True),
            (high + 1e-6, False),
        ):
            lower, upper = boundaries(trials, p, budgets)[-1]
            assert (lower < count < upper) == inside, (trials, count, p, inside)
    trials = (10, 20, 30)
    budgets = tuple(spent(t, 0.1, "obrien-fleming") / 2 for t in (1 / 3, 2 / 3, 1))
    for p in (0.03, 0.2, 0.5, 0.77):
        assert sum(crossing(trials, boundaries(trials, p, budgets), p)) <= 0.1 + 1e-12


@pytest.mark.heavy
def test_decisions_and_coverage_simulated():
    """Simulated pairs through the rule: no difference rarely declared, +-margin equivalence
    declared when the policies agree, and the difference interval at the stop covers."""
    rng = np.random.default_rng(11)
    design = PairedDecisionDesign.in_chunks(50, 400, alpha=0.1, margin=0.15)
    reps = 150
    cases = {"null": (0.05, 0.05), "small": (0.0, 0.02), "large": (0.05, 0.35)}
    for name, (p_a, p_b) in cases.items():
        decisions, covered = [], 0
        for _ in range(reps):
            u = rng.random(design.cap)
            a = u < p_a
            b = (u >= p_a) & (u < p_a + p_b)
            look = design.run(a, b)[-1]
            decisions.append(look.decision)
            covered += look.ci_low <= p_b - p_a <= look.ci_high
        counts = {d: decisions.count(d) / reps for d in set(decisions)}
        # 150 runs: a rate of 0.1 has a standard error of 0.025
        assert covered / reps >= 0.9 - 3 * 0.025, (name, covered)
        if name == "null":
            assert counts.get("better", 0) + counts.get("worse", 0) <= design.alpha_q + 0.075
        elif name == "small":
            assert counts.get("equivalent", 0) > 0.9
        else:
            assert counts.get("better", 0) > 0.9


def test_bad_designs_are_config_errors():
    with pytest.raises(ConfigError, match="margin must lie in"):
        PairedDecisionDesign((10,), margin=1.5)
    with pytest.raises(ConfigError, match="alpha must lie in"):
        PairedDecisionDesign((10,), alpha=0)
    with pytest.raises(ConfigError, match="looks must be increasing"):
        PairedDecisionDesign((10, 5))
