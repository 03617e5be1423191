"""Planning `eval --decide`'s cap: the per-path decision probabilities against the design's own
rule and against the exact crossing computation, the path average against every path, and the
planned cap's power and expected seeds against simulated paired outcomes run through the rule
(stated Monte-Carlo error)."""

import itertools

import numpy as np
import pytest
from scipy import stats as sps

from openral_mjx.core.errors import ConfigError
from openral_mjx.stats import decide_planning
from openral_mjx.stats.decide_planning import (
    _equivalence,
    decide_outcome,
    decisions_given_path,
    plan_decide,
)
from openral_mjx.stats.paired_sequential import PairedDecisionDesign, boundaries, crossing


def simulate(
    monkeypatch, design: PairedDecisionDesign, difference: float, psi: float, reps: int, seed: int
):
    """Decisions and seeds used over `reps` simulated pairs of runs through the design's rule
    (`run`): per seed, only A with (psi - d) / 2, only B with (psi + d) / 2, else concordant.
    The interval at the stop, which no decision reads, is skipped (it is most of the time)."""
    monkeypatch.setattr(PairedDecisionDesign, "interval", lambda *_: (0.0, 0.0))
    rng = np.random.default_rng(seed)
    only_a, only_b = (psi - difference) / 2, (psi + difference) / 2
    decisions, seeds = [], []
    for _ in range(reps):
        u = rng.random(design.cap)
        a, b = u < only_a, (u >= only_a) & (u < only_a + only_b)
        last = design.run(a, b)[-1]
        decisions.append(last.decision)
        seeds.append(last.n)
    return np.array(decisions), np.array(seeds)


def test_regions_are_the_designs_own_decisions():
    """Along random discordant paths, every count of B at every look is classed as the
    design's `look` classes it (better, worse, equivalent, or go on)."""
    design = PairedDecisionDesign.in_chunks(10, 30, alpha=0.1, margin=0.3)
    rng = np.random.default_rng(4)
    for _ in range(3):
        path = tuple(int(x) for x in np.cumsum(rng.binomial(10, rng.uniform(0.1, 0.9), 3)))
        lower_upper = boundaries(path, 0.5, design.budgets(design.alpha_q, 2))
        for k, d in enumerate(path):
            lower, upper = lower_upper[k]
            eq = _equivalence(design, path, k)
            for w in range(d + 1):
                only_a = [*path[:k], d - w]
                only_b = [0] * k + [w]
                got = design.look(k, only_a, only_b).decision
                if w >= upper:
                    want = "better"
                elif w <= lower:
                    want = "worse"
                elif eq is not None and eq[0] <= w <= eq[1]:
                    want = "equivalent"
                else:
                    want = "inconclusive" if k == 2 else None
                assert got == want, (path, k, w)


def test_without_margin_it_is_the_exact_crossing_probability():
    """No margin: per path, better and worse are `crossing`'s upper and lower probabilities,
    and summed over every path (few here, so exact) they are the power computed directly."""
    design = PairedDecisionDesign.in_chunks(6, 18)
    q, psi = 0.8, 0.5
    direct_better = direct_worse = 0.0
    for incs in itertools.product(range(7), repeat=3):
        path = tuple(int(x) for x in np.cumsum(incs))
        prob = float(np.prod([sps.binom.pmf(i, 6, psi) for i in incs]))
        bounds = boundaries(path, 0.5, design.budgets(design.alpha_q, 2))
        low, high = crossing(path, bounds, q)
        per = decisions_given_path(design, path, q)
        assert per[:, 0].sum() == pytest.approx(high, abs=1e-12)
        assert per[:, 1].sum() == pytest.approx(low, abs=1e-12)
        direct_better += prob * high
        direct_worse += prob * low
    out = decide_outcome(design, psi * (2 * q - 1), psi)
    assert out.se_power == 0  # 343 paths: summed exactly
    assert out.better == pytest.approx(direct_better, abs=1e-12)
    assert out.worse == pytest.approx(direct_worse, abs=1e-12)


def test_sampled_paths_agree_with_every_path(monkeypatch):
    """Forced to sample 400 discordant paths, the power and expected seeds fall within four
    of their stated standard errors of the exact sums."""
    design = PairedDecisionDesign.in_chunks(10, 40, alpha=0.05)
    exact = decide_outcome(design, 0.15, 0.35)
    monkeypatch.setattr(decide_planning, "EXACT_PATHS", 0)
    sampled = decide_outcome(design, 0.15, 0.35, paths=400, seed=1)
    assert sampled.se_power > 0 and sampled.se_seeds > 0
    assert abs(sampled.better - exact.better) < 4 * sampled.se_power
    assert abs(sampled.expected_seeds - exact.expected_seeds) < 4 * sampled.se_seeds


def test_planned_cap_reaches_the_power_and_simulation_agrees(monkeypatch):
    """+20 points at discordance 40%, looks every 20 seeds, 80% power: the cap is the first
    whole look count that reaches it (one look fewer does not), and 600 simulated runs of
    the design at that cap decide "better" and use seeds as computed (power SE ~1.5 points)."""
    plan = plan_decide(0.2, 0.4, power=0.8, looks_every=20)
    design, effect = plan.design, plan.effect
    assert design is not None and effect is not None and plan.null is not None
    assert effect.better >= 0.8 and design.cap % 20 == 0
    fewer = PairedDecisionDesign.in_chunks(20, design.cap - 20)
    assert decide_outcome(fewer, 0.2, 0.4).better < 0.8
    decisions, seeds = simulate(monkeypatch, design, 0.2, 0.4, 600, seed=2)
    se = np.sqrt(effect.better * (1 - effect.better) / 600) + effect.se_power
    assert abs((decisions == "better").mean() - effect.better) < 4 * se
    assert abs(seeds.mean() - effect.expected_seeds) < 4 * seeds.std() / np.sqrt(600)
    # no difference: rarely a decision, nearly always the cap; the simulation agrees
    assert plan.null.better + plan.null.worse <= design.alpha_q + 1e-9
    decisions, seeds = simulate(monkeypatch, design, 0.0, 0.4, 600, seed=3)
    assert abs(seeds.mean() - plan.null.expected_seeds) < 4 * seeds.std() / np.sqrt(600) + 1
    # the sequential design's cap costs a little over the fixed-size test, and saves on average
    assert plan.fixed_seeds is not None and design.cap >= plan.fixed_seeds - 20
    assert effect.expected_seeds < plan.fixed_seeds


def test_worse_and_equivalence_with_a_margin(monkeypatch):
    """B worse by 25 points: the power is P(worse). With a margin of 45 points and few
    discordant seeds, no difference often ends "equivalent", some of it before the cap:
    computed over every path, and 400 simulated runs agree (SE ~2.5 points)."""
    plan = plan_decide(-0.25, 0.45, power=0.7, looks_every=25)
    assert plan.effect is not None and plan.effect.worse >= 0.7 > plan.effect.better
    design = PairedDecisionDesign.in_chunks(6, 18, alpha=0.1, margin=0.45)
    null = decide_outcome(design, 0.0, 0.15)
    assert null.se_power == 0 and 0.3 < null.equivalent < 0.95 and null.expected_seeds < 17.5
    decisions, seeds = simulate(monkeypatch, design, 0.0, 0.15, 400, seed=5)
    eq = null.equivalent
    assert abs((decisions == "equivalent").mean() - eq) < 4 * np.sqrt(eq * (1 - eq) / 400)
    assert abs(seeds.mean() - null.expected_seeds) < 4 * seeds.std() / np.sqrt(400)


def test_not_reached_and_bad_values():
    plan = plan_decide(0.01, 0.5, looks_every=100, max_seeds=1000)
    assert plan.design is None and plan.fixed_seeds is None
    with pytest.raises(ConfigError, match=r"within \+-discordance = \[-0.1, 0.1\]"):
        plan_decide(0.2, 0.1)
    with pytest.raises(ConfigError, match="discordance must lie in"):
        plan_decide(0.1, 0)
    with pytest.raises(ConfigError, match="power must lie in"):
        plan_decide(0.1, 0.2, power=1)
    with pytest.raises(ConfigError, match="unknown spending function 'x'"):
        plan_decide(0.1, 0.2, spending="x")
