"""The cap of `eval --decide`'s sequential design for a target power, and the seeds it expects
to use: `paired_sequential`'s design, evaluated by its own exact machinery.

Given a path of discordant counts d_1..d_K at the looks, B's share of them is a binomial walk at
q = (1 + delta / psi) / 2, and the design's boundaries along that path are fixed: the
probability of each decision at each look is then exact, by the dynamic programme `crossing`
uses (advance the count's distribution, take out what crosses). The discordant path itself is
random (Binomial(looks_every, psi) per look); its distribution is summed over exactly where the
paths are few (`EXACT_PATHS`), else averaged over `paths` sampled paths (the same ones for every
cap, so caps compare on common random numbers), with the Monte-Carlo standard error stated:
only the discordant counts are sampled, so that error is far below a plain simulation's.

The cap is searched over whole looks (multiples of `looks_every`): doubling, then bisection,
assuming the power grows with the cap (as it does up to the test's discreteness).
"""

from __future__ import annotations

import dataclasses
import functools
import itertools

import numpy as np
from scipy import stats as sps

from openral_mjx.core.errors import ConfigError
from openral_mjx.stats.paired_sequential import (
    PairedDecisionDesign,
    add_binomial,
    boundaries,
    repeated_interval,
)
from openral_mjx.stats.planning import PairedDesign, plan_paired

EXACT_PATHS = 4096  # sum over every discordant path when there are at most this many
PATHS = 300  # sampled discordant paths otherwise


@dataclasses.dataclass(frozen=True)
class DecideOutcome:
    """A design's behaviour at one effect: P(better), P(worse), P(equivalent) and the expected
    seeds used, each with its Monte-Carlo standard error (0 where summed exactly)."""

    better: float
    worse: float
    equivalent: float
    expected_seeds: float
    se_power: float
    se_seeds: float


def _equivalence(
    design: PairedDecisionDesign, path: tuple[int, ...], k: int
) -> tuple[int, int] | None:
    """Values of B's count at look k (within the test's continuation region) that the
    design calls equivalent, as (low, high), or None (`PairedDecisionDesign.within_margin`
    as a region of counts)."""
    if design.margin is None:
        return None
    return _equivalence_cached(design, path[: k + 1])


@functools.lru_cache(maxsize=65536)
def _equivalence_cached(
    design: PairedDecisionDesign, path: tuple[int, ...]
) -> tuple[int, int] | None:
    """`_equivalence` at the last look of `path` (paths share prefixes: cached)."""
    assert design.margin is not None
    k = len(path) - 1
    psi_high = _psi_high(design, k, path[k])
    if psi_high < design.margin:
        return 0, path[k]
    q_star = (1 + design.margin / psi_high) / 2
    budgets = design.budgets(design.alpha_q, k)
    low = boundaries(path[: k + 1], 1 - q_star, budgets)[-1][1]
    high = boundaries(path[: k + 1], q_star, budgets)[-1][0]
    return (low, high) if low <= high else None


@functools.lru_cache(maxsize=65536)
def _psi_high_cached(looks: tuple[int, ...], budgets: tuple[float, ...], d: int) -> float:
    return repeated_interval(looks, d, budgets, "high")[1]


def _psi_high(design: PairedDecisionDesign, k: int, d: int) -> float:
    return _psi_high_cached(design.looks[: k + 1], design.budgets(design.alpha_psi, k), d)


def decisions_given_path(
    design: PairedDecisionDesign, path: tuple[int, ...], q: float
) -> np.ndarray:
    """(K, 3) exact probabilities of stopping at look k as better, worse or equivalent, given
    the cumulative discordant counts `path` at the K looks and B's share q of them; what is
    left at the last look is inconclusive."""
    k_looks = len(design.looks)
    bounds = boundaries(path, 0.5, design.budgets(design.alpha_q, k_looks - 1))
    out = np.zeros((k_looks, 3))
    mass, prev = np.ones(1), 0
    for k, (d, (lower, upper)) in enumerate(zip(path, bounds, strict=True)):
        mass, prev = add_binomial(mass, d - prev, q), d
        out[k, 0] = mass[upper:].sum()
        out[k, 1] = mass[: lower + 1].sum() if lower >= 0 else 0.0
        mass[upper:] = 0.0
        mass[: max(lower + 1, 0)] = 0.0
        eq = _equivalence(design, path, k)
        if eq is not None:
            out[k, 2] = mass[eq[0] : eq[1] + 1].sum()
            mass[eq[0] : eq[1] + 1] = 0.0
    return out


def _paths(design: PairedDecisionDesign, psi: float, seed: int, n_paths: int):
    """(paths, weights, exact): every discordant path with its probability where they are few,
    else `n_paths` sampled ones with equal weights (path i from its own stream, so its first
    looks are the same whatever the number of looks)."""
    sizes = np.diff((0, *design.looks))
    if int(np.prod(sizes + 1.0)) <= EXACT_PATHS:
        paths, weights = [], []
        for incs in itertools.product(*(range(s + 1) for s in sizes)):
            probs = [sps.binom.pmf(i, s, psi) for i, s in zip(incs, sizes, strict=True)]
            weights.append(np.prod(probs))
            paths.append(tuple(int(x) for x in np.cumsum(incs)))
        return paths, np.array(weights), True
    incs = [np.random.default_rng([seed, i]).binomial(sizes, psi) for i in range(n_paths)]
    paths = [tuple(int(x) for x in row) for row in np.cumsum(incs, axis=1)]
    return paths, np.full(n_paths, 1 / n_paths), False


def decide_outcome(
    design: PairedDecisionDesign,
    difference: float,
    discordance: float,
    paths: int = PATHS,
    seed: int = 0,
) -> DecideOutcome:
    """`design`'s decision probabilities and expected seeds when B - A = `difference` and a
    seed is discordant with probability `discordance` (see module)."""
    check_effect(difference, discordance, allow_zero=True)
    q = (1 + difference / discordance) / 2
    chosen, weights, exact = _paths(design, discordance, seed, paths)
    per_path = np.array([decisions_given_path(design, p, q) for p in chosen])  # (P, K, 3)
    stop = per_path.sum(axis=2)
    stop[:, -1] = 1 - stop[:, :-1].sum(axis=1)  # the cap stops whatever is left
    seeds = stop @ np.array(design.looks, float)
    totals = per_path.sum(axis=1)  # (P, 3)
    power_each = totals[:, 0] if difference >= 0 else totals[:, 1]
    mean = weights @ totals

    def se(x: np.ndarray) -> float:
        return 0.0 if exact else float(np.std(x, ddof=1) / np.sqrt(len(x)))

    return DecideOutcome(
        float(mean[0]),
        float(mean[1]),
        float(mean[2]),
        float(weights @ seeds),
        se(power_each),
        se(seeds),
    )


def check_effect(difference: float, discordance: float, allow_zero: bool = False) -> None:
    """Raise `ConfigError` unless 0 < discordance <= 1 and |difference| <= discordance (the
    difference is the discordant seeds' net share), difference non-zero unless allowed."""
    if not 0 < discordance <= 1:
        raise ConfigError(f"discordance must lie in (0, 1], got {discordance}")
    if abs(difference) > discordance + 1e-12 or (difference == 0 and not allow_zero):
        raise ConfigError(
            f"difference must be non-zero and within +-discordance = [{-discordance:g}, "
            f"{discordance:g}] (only the discordant seeds differ), got {difference}"
        )


@dataclasses.dataclass(frozen=True)
class DecidePlan:
    """The smallest cap (a whole number of looks) at which `design` decides the stated effect
    with at least the target power (`design` None: not within `max_seeds`); its behaviour
    under the effect (`effect`) and under no difference (`null`), and the fixed-size exact
    McNemar test's seeds at the same level and power (`fixed_seeds`, None past `max_seeds`)."""

    difference: float
    discordance: float
    target: float
    looks_every: int
    max_seeds: int
    design: PairedDecisionDesign | None
    effect: DecideOutcome | None
    null: DecideOutcome | None
    fixed_seeds: int | None


def plan_decide(
    difference: float,
    discordance: float,
    power: float = 0.8,
    looks_every: int = 256,
    alpha: float = 0.05,
    margin: float | None = None,
    spending: str = "obrien-fleming",
    max_seeds: int = 1_000_000,
    paths: int = PATHS,
) -> DecidePlan:
    """The cap of `eval --decide` (looks every `looks_every` seeds) for `power` at the stated
    effect (see module)."""
    check_effect(difference, discordance)
    if not 0 < power < 1:
        raise ConfigError(f"power must lie in (0, 1), got {power}")
    if looks_every < 1 or max_seeds < looks_every:
        raise ConfigError(
            f"--looks-every must be a positive seed count at most --max-seeds ({max_seeds:,}), got "
            f"{looks_every}"
        )
    PairedDecisionDesign((looks_every,), alpha, margin, spending)  # checks the design's values

    def design(looks: int) -> PairedDecisionDesign:
        return PairedDecisionDesign.in_chunks(
            looks_every, looks * looks_every, alpha, margin, spending
        )

    @functools.lru_cache
    def outcome(looks: int) -> DecideOutcome:
        return decide_outcome(design(looks), difference, discordance, paths)

    def power_of(looks: int) -> float:
        o = outcome(looks)
        return o.better if difference > 0 else o.worse

    # the fixed-size exact McNemar test at the sequential test's level: A's rate does not
    # matter to it, only the discordance and B's share
    fixed_design = PairedDesign(0.5 - difference / 2, difference, discordance, design(1).alpha_q)
    fixed = plan_paired(fixed_design, power, max_seeds).seeds
    most = max_seeds // looks_every
    lo = 0
    hi = max(1, min(most, (fixed or max_seeds) // looks_every))
    while power_of(hi) < power:
        if hi == most:
            return DecidePlan(
                difference, discordance, power, looks_every, max_seeds, None, None, None, fixed
            )
        lo, hi = hi, min(most, 2 * hi)
    while hi - lo > 1:  # power_of(hi) >= power; lo == 0 or power_of(lo) < power
        mid = (lo + hi) // 2
        lo, hi = (lo, mid) if power_of(mid) >= power else (mid, hi)
    chosen = design(hi)
    null = decide_outcome(chosen, 0.0, discordance, paths)
    return DecidePlan(
        difference, discordance, power, looks_every, max_seeds, chosen, outcome(hi), null, fixed
    )


def format_decide_plan(plan: DecidePlan) -> str:
    """What `plan decide` prints: the cap, its power, the seeds it expects to use under the
    effect and under no difference, and the fixed-size test's seeds for comparison."""
    pts = f"{100 * plan.difference:+.1f} points"
    direction = "better" if plan.difference > 0 else "worse"
    given = (
        f"B - A = {pts} at discordance {100 * plan.discordance:.1f}% (only A succeeds on "
        f"{50 * (plan.discordance - plan.difference):.1f}% of seeds, only B on "
        f"{50 * (plan.discordance + plan.difference):.1f}%)"
    )
    fixed = f"more than {plan.max_seeds:,}" if plan.fixed_seeds is None else f"{plan.fixed_seeds:,}"
    if plan.design is None or plan.effect is None or plan.null is None:
        return (
            f"not reached within {plan.max_seeds:,} seeds (looks every {plan.looks_every:,}): "
            f"{given}; a fixed-size exact McNemar test needs {fixed} seeds"
        )
    d, e, z = plan.design, plan.effect, plan.null
    power = e.better if plan.difference > 0 else e.worse
    mc = "" if e.se_power == 0 else f", Monte-Carlo SE {100 * e.se_power:.1f} points"
    margin = "" if d.margin is None else f" --margin {d.margin:g}"
    lines = [
        f"cap {d.cap:,} seeds ({len(d.looks)} looks of {plan.looks_every:,}) decides B "
        f"{direction} with {100 * power:.1f}% power (target {100 * plan.target:g}%{mc}) when "
        f"{given}",
        f"design: {d.describe()}",
        f"expected seeds: {e.expected_seeds:,.0f} at that effect; {z.expected_seeds:,.0f} if "
        f"there is no difference (then better or worse with probability "
        f"{z.better + z.worse:.3f}, equivalent {z.equivalent:.3f})",
        f"a fixed-size exact McNemar test at level {d.alpha_q:.3g} needs {fixed} seeds for the "
        "same power",
        f"run: eval ... --compare-with A.json --decide --n-envs {plan.looks_every} "
        f"--n-episodes {d.cap} --alpha {d.alpha:g} --spending {d.spending}{margin}",
    ]
    return "\n".join(lines)


__all__ = [
    "DecideOutcome",
    "DecidePlan",
    "check_effect",
    "decide_outcome",
    "decisions_given_path",
    "format_decide_plan",
    "plan_decide",
]
