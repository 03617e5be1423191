"""Sample-size plans against independent oracles: the exact McNemar power against a full
enumeration of the 2x2 tables (trinomial counts of only-A and only-B seeds) and against
simulated paired experiments; the paired plan's "fewest seeds" and "stays above" claims
against the enumerated power at every count; the interval plan against simulated Wilson
intervals.

Monte-Carlo tolerances are 4.5 standard errors of the simulated proportion or mean (a false
failure about once in 150,000 runs per check).
"""

import math

import numpy as np
import pytest
from scipy import special
from scipy import stats as sps

from openral_mjx.core.errors import ConfigError
from openral_mjx.stats import (
    PairedDesign,
    Pilot,
    episodes_for_halfwidth,
    format_interval_plan,
    format_paired_plan,
    mcnemar_critical_counts,
    mcnemar_exact_pvalue,
    mcnemar_power,
    paired_comparison,
    plan_paired,
    wilson_interval,
)


@pytest.mark.parametrize("alpha", [0.01, 0.05, 0.2])
def test_critical_counts_are_the_tests_own(alpha):
    """k_d is the largest smaller count the test rejects at, found by trying every count."""
    d = np.arange(300)
    expected = []
    for m in d:
        x = np.arange(m // 2 + 1)
        rejects = np.atleast_1d(mcnemar_exact_pvalue(m - x, x) <= alpha)
        expected.append(x[rejects].max() if rejects.any() else -1)
    np.testing.assert_array_equal(mcnemar_critical_counts(d, alpha), expected)


class Enumerated:
    """The exact McNemar test's power at every n up to `top`, by summing the trinomial
    probability of (only_a, only_b, concordant) counts over the tables it rejects."""

    def __init__(self, design: PairedDesign, top: int):
        y, x = np.meshgrid(np.arange(top + 1), np.arange(top + 1), indexing="ij")
        self.y, self.x = y, x  # only_a, only_b
        inside = x + y <= top
        self.rejects = np.zeros_like(inside)
        self.rejects[inside] = mcnemar_exact_pvalue(y[inside], x[inside]) <= design.alpha
        self.log_fact = special.gammaln(np.arange(top + 1) + 1.0)  # log k!
        self.design = design

    def power(self, n: int) -> float:
        y, x = self.y[: n + 1, : n + 1], self.x[: n + 1, : n + 1]
        rest = n - x - y
        ok = rest >= 0
        d = self.design
        with np.errstate(divide="ignore", invalid="ignore"):
            log_p = (
                self.log_fact[n]
                - self.log_fact[x]
                - self.log_fact[y]
                - self.log_fact[np.where(ok, rest, 0)]
                + special.xlogy(x, d.only_b)
                + special.xlogy(y, d.only_a)
                + special.xlogy(np.where(ok, rest, 0), 1 - d.discordance)
            )
        p = np.where(ok, np.exp(log_p), 0.0)
        return float(p[self.rejects[: n + 1, : n + 1]].sum())


# (design, power target): a discordance from a pilot's range; the independence value; a strict
# alpha; and discordance 1 (D = n: no averaging over D, so the power zigzags in n)
PLANS = [
    (PairedDesign(0.6, 0.1, 0.2), 0.8),
    (PairedDesign.independent(0.3, -0.15), 0.8),
    (PairedDesign(0.5, 0.3, 0.3, alpha=0.01), 0.9),
    (PairedDesign(0.4, 0.2, 1.0), 0.8),
]


@pytest.mark.parametrize("design, target", PLANS)
def test_plan_is_the_fewest_seeds_and_says_where_the_power_stays(design, target):
    plan = plan_paired(design, target)
    top = 2 * plan.stable_seeds
    enumerated = Enumerated(design, top)
    power = np.array([enumerated.power(n) for n in range(1, top + 1)])  # power[n - 1]
    reached = np.nonzero(power >= target)[0] + 1
    assert plan.seeds == reached[0]
    assert plan.power == pytest.approx(power[plan.seeds - 1], abs=1e-9)
    s = plan.stable_seeds
    assert (power[s - 1 : 2 * s] >= target).all()
    for fewer in range(plan.seeds, s):  # each smaller start has a dip in its [n, 2n]
        assert (power[fewer - 1 : 2 * fewer] < target).any()
    for n in (1, plan.seeds // 2, plan.seeds, top):
        assert mcnemar_power(n, design) == pytest.approx(power[n - 1], abs=1e-9)


def test_the_power_is_not_monotone_where_the_discordance_is_one():
    """With every seed discordant the power is the exact test's at d = n, which rises in
    steps: the plan's first count is followed by dips, and `stable_seeds` lies past them."""
    design, target = PLANS[-1]
    plan = plan_paired(design, target)
    after = [mcnemar_power(n, design) for n in range(plan.seeds, plan.stable_seeds)]
    assert min(after) < target and plan.stable_seeds > plan.seeds
    assert f"at {plan.stable_seeds - 1:,} it is below" in format_paired_plan(plan)


def simulate_power(design: PairedDesign, n: int, reps: int, rng) -> float:
    """Share of `reps` simulated paired experiments of `n` seeds in which `compare`'s test
    (exact McNemar, p <= alpha) rejects: per seed, only A succeeds with p_only_a, only B with
    p_only_b."""
    u = rng.random((reps, n))
    only_a = (u < design.only_a).sum(axis=1)
    only_b = ((u >= design.only_a) & (u < design.only_a + design.only_b)).sum(axis=1)
    return float(np.mean(mcnemar_exact_pvalue(only_a, only_b) <= design.alpha))


@pytest.mark.parametrize("design, target", PLANS[:3])
def test_exact_power_matches_simulated_experiments(design, target):
    plan = plan_paired(design, target)
    reps = 4000
    simulated = simulate_power(design, plan.seeds, reps, np.random.default_rng(7))
    se = math.sqrt(plan.power * (1 - plan.power) / reps)
    assert abs(simulated - plan.power) <= 4.5 * se, (simulated, plan.power)


def test_more_discordance_needs_more_seeds_and_a_difference_fewer():
    """Power falls with the discordance at a fixed difference (q nearer 1/2) and rises with the
    difference: the plans move the way a user expects."""
    seeds = [plan_paired(PairedDesign(0.5, 0.1, psi)).seeds for psi in (0.1, 0.2, 0.4, 0.8)]
    assert seeds == sorted(seeds) and len(set(seeds)) == 4
    seeds = [plan_paired(PairedDesign(0.5, dl, 0.4)).seeds for dl in (0.05, 0.1, 0.2)]
    assert seeds == sorted(seeds, reverse=True)
    # the direction does not matter: the test is two-sided and symmetric
    assert (
        plan_paired(PairedDesign(0.5, -0.1, 0.3)).seeds
        == plan_paired(PairedDesign(0.4, 0.1, 0.3)).seeds
    )


def test_normal_approximation_is_close_for_large_counts():
    """Far from the discreteness, the exact plan is near Connor's (1987) normal-approximation
    sample size (z_{a/2} sqrt(psi) + z_b sqrt(psi - delta^2))^2 / delta^2, a little above it:
    the exact conditional test is conservative."""
    design = PairedDesign(0.5, 0.02, 0.3)
    z_a, z_b = sps.norm.isf(0.025), sps.norm.isf(0.2)
    connor = (z_a * math.sqrt(0.3) + z_b * math.sqrt(0.3 - 0.02**2)) ** 2 / 0.02**2
    assert connor <= plan_paired(design).seeds <= 1.03 * connor


def test_not_reached_within_the_cap():
    design = PairedDesign(0.6, 0.1, 0.2)
    full = plan_paired(design)
    short = plan_paired(design, cap=full.seeds - 1)
    assert short.seeds is None and short.stable_seeds is None
    assert short.power_at_cap == pytest.approx(mcnemar_power(full.seeds - 1, design))
    assert short.power_at_cap < 0.8
    assert "not reached within 167 paired seeds".replace("167", f"{full.seeds - 1}") in (
        format_paired_plan(short)
    )
    # reached, but twice it is past the cap: "stays" is not checked
    assert plan_paired(design, cap=full.seeds).stable_seeds is None


@pytest.mark.parametrize(
    "make, needle",
    [
        (lambda: PairedDesign(1.2, 0.1, 0.2), "rate must lie in [0, 1], got 1.2"),
        (lambda: PairedDesign(0.6, 0.5, 0.6), "valid [-0.6, 0.4] except 0 at rate 0.6, got 0.5"),
        (lambda: PairedDesign(0.6, 0.0, 0.2), "difference must be non-zero"),
        (lambda: PairedDesign(0.6, 0.1, 0.05), "= [0.1, 0.7] at rates 0.6 (A) and 0.7 (B), got"),
        (lambda: PairedDesign(0.1, 0.1, 0.5), "= [0.1, 0.3]"),
        (lambda: PairedDesign(0.6, 0.1, 0.2, alpha=1.0), "alpha must lie in (0, 1), got 1.0"),
        (lambda: PairedDesign.independent(-0.1, 0.1), "rate must lie in [0, 1], got -0.1"),
        (lambda: plan_paired(PairedDesign(0.6, 0.1, 0.2), 1.5), "power must lie in (0, 1)"),
        (lambda: mcnemar_power(0, PairedDesign(0.6, 0.1, 0.2)), "got 0"),
    ],
)
def test_bad_values_name_themselves_and_the_range(make, needle):
    with pytest.raises(ConfigError) as e:
        make()
    assert needle in str(e.value)


def test_independence_discordance():
    design = PairedDesign.independent(0.6, 0.1)
    assert design.discordance == pytest.approx(0.6 * 0.3 + 0.7 * 0.4)
    assert design.source == "independence"
    assert "if outcomes were independent" in format_paired_plan(plan_paired(design))


def test_pilot_measures_the_discordance_on_common_seeds():
    rng = np.random.default_rng(3)
    a = rng.random(400) < 0.6
    b = np.where(rng.random(400) < 0.2, ~a, a)  # about 20% of seeds flip
    c = paired_comparison(a, b)
    pilot = Pilot.from_comparison(c)
    assert pilot.discordance == (c.only_a + c.only_b) / 400
    design = pilot.design(0.1)
    assert design.rate_a == c.successes_a / 400 and design.source == "reports"
    upper = pilot.design(0.1, upper=True)
    assert upper.discordance == pytest.approx(wilson_interval(c.only_a + c.only_b, 400)[1])
    assert plan_paired(upper).seeds > plan_paired(design).seeds
    with pytest.raises(ConfigError, match=r"fewer than a difference of 0\.5 needs"):
        pilot.design(0.5, rate=0.4)
    text = format_paired_plan(plan_paired(design), pilot, " of a.json and b.json")
    assert f"measured on 400 common seeds of a.json and b.json (only A {c.only_a}" in text


def test_interval_plan_by_simulated_wilson_intervals():
    """At the planned n, simulated Wilson half-widths average at most the target (the
    half-width is concave in the observed rate, so its mean is at most its value at the mean)
    and within 3% of it."""
    rng = np.random.default_rng(11)
    reps = 4000
    for rate, halfwidth in ((0.6, 0.03), (0.9, 0.02), (0.97, 0.01)):
        n = episodes_for_halfwidth(halfwidth, rate)
        low, high = wilson_interval(rng.binomial(n, rate, reps), n)
        widths = (np.asarray(high) - np.asarray(low)) / 2
        se = widths.std(ddof=1) / math.sqrt(reps)
        assert widths.mean() <= halfwidth + 4.5 * se
        assert widths.mean() >= 0.97 * halfwidth - 4.5 * se
    text = format_interval_plan(0.03, 0.6)
    assert text.startswith(f"{episodes_for_halfwidth(0.03, 0.6):,} seeds give a 95% Wilson")
    assert f"{episodes_for_halfwidth(0.03, 0.5):,} seeds" in text.splitlines()[1]
