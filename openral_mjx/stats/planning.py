"""Sample sizes before a run: how many paired seeds to detect a difference between two
policies, and how many episodes for an interval of a given half-width on one.

Paired seeds (both policies run on the same seeds) are compared by the exact McNemar test on
the discordant seeds, which is what `compare` does, so the plan computes that test's power
exactly. Per seed the pair of outcomes falls in one of four cells; only the discordant ones
count: "only A succeeds" with probability p_a_only, "only B" with p_b_only. The difference
to detect is delta = rate_B - rate_A = p_b_only - p_a_only and the discordance is
psi = p_a_only + p_b_only. Over n seeds the number of discordant seeds is D ~ Binomial(n, psi),
and given D = d the seeds favouring B are Binomial(d, q) with q = p_b_only / psi, so

    power(n) = sum_d P(D = d) * P(the exact McNemar test rejects at level alpha | d, q).

The rates themselves do not enter beyond delta and psi; they bound psi (every cell
probability must lie in [0, 1]) and give the independence value of psi when none is known.

The exact test's power is not monotone in n (its rejection region moves in integer steps), so
the plan reports the fewest seeds whose power reaches the target, found by checking every n
from a proven lower bound (an upper bound on the power that, unlike the power, does not fall
with n: see `_Tables`), and the fewest from which it stays at or above the target through
twice that many seeds (a lower bound that does not fall with n covers the far part of that
range: see `_stays`). The Python loop runs over the few n between the bounds only.

References: McNemar (1947), Psychometrika 12: 153-157; Fagerland, Lydersen & Laake (2017),
"Statistical Analysis of Contingency Tables", ch. 8 (the exact conditional McNemar test);
Connor (1987), Biometrics 43: 207-211 (the normal-approximation sample size).
"""

from __future__ import annotations

import dataclasses
import math
from collections.abc import Callable, Iterator

import numpy as np
from scipy import stats as sps

from openral_mjx.core.errors import ConfigError, unknown
from openral_mjx.report import EvalReport
from openral_mjx.stats.comparison import Comparison, mcnemar_exact_pvalue
from openral_mjx.stats.intervals import episodes_for_halfwidth, wilson_interval

PLAN_CAP = 1_000_000  # the most seeds a plan searches
DISCORDANCE_SOURCES = ("stated", "reports", "independence")


def _check_open(name: str, value: float) -> None:
    if not 0 < value < 1:
        raise ConfigError(f"{name} must lie in (0, 1), got {value}")


def independence_discordance(rate_a: float, rate_b: float) -> float:
    """Discordance if the two policies' outcomes on a seed were independent:
    rate_a (1 - rate_b) + rate_b (1 - rate_a). Seeds that are hard for one policy are
    usually hard for the other too, which lowers it, so this tends to over-state the seeds
    needed."""
    return rate_a * (1 - rate_b) + rate_b * (1 - rate_a)


def discordance_range(rate_a: float, rate_b: float) -> tuple[float, float]:
    """The discordances possible at these rates: from |rate_b - rate_a| (one policy succeeds
    wherever the other does) to min(rate_a + rate_b, 2 - rate_a - rate_b) (they never both
    succeed, or never both fail)."""
    return abs(rate_b - rate_a), min(rate_a + rate_b, 2 - rate_a - rate_b)


@dataclasses.dataclass(frozen=True)
class PairedDesign:
    """What a paired plan assumes: A's success rate, the difference rate_B - rate_A to detect,
    the discordance (probability that exactly one policy succeeds on a seed) and the two-sided
    level of the exact McNemar test. `source` says where the discordance came from
    (`DISCORDANCE_SOURCES`)."""

    rate_a: float
    difference: float
    discordance: float
    alpha: float = 0.05
    source: str = "stated"

    def __post_init__(self) -> None:
        if not 0 <= self.rate_a <= 1:
            raise ConfigError(f"rate must lie in [0, 1], got {self.rate_a}")
        low, high = -self.rate_a, 1 - self.rate_a
        if self.difference == 0 or not low - 1e-12 <= self.difference <= high + 1e-12:
            raise ConfigError(
                f"difference must be non-zero and keep B's rate (rate + difference) in [0, 1]: "
                f"valid [{low:g}, {high:g}] except 0 at rate {self.rate_a:g}, "
                f"got {self.difference}"
            )
        lo, hi = discordance_range(self.rate_a, self.rate_b)
        if not lo - 1e-12 <= self.discordance <= hi + 1e-12:
            raise ConfigError(
                f"discordance must lie in [|difference|, min(rate_A + rate_B, 2 - rate_A - "
                f"rate_B)] = [{lo:g}, {hi:g}] at rates {self.rate_a:g} (A) and "
                f"{self.rate_b:g} (B), got {self.discordance}"
            )
        _check_open("alpha", self.alpha)
        if self.source not in DISCORDANCE_SOURCES:
            raise unknown("discordance source", self.source, DISCORDANCE_SOURCES)

    @classmethod
    def independent(cls, rate_a: float, difference: float, alpha: float = 0.05) -> PairedDesign:
        """The design whose discordance is `independence_discordance` of the two rates."""
        if not 0 <= rate_a <= 1:
            raise ConfigError(f"rate must lie in [0, 1], got {rate_a}")
        psi = independence_discordance(rate_a, min(1.0, max(0.0, rate_a + difference)))
        return cls(rate_a, difference, psi, alpha, "independence")

    @property
    def rate_b(self) -> float:
        return min(1.0, max(0.0, self.rate_a + self.difference))  # 0.9 + 0.1 is 1 + 2e-16

    @property
    def only_a(self) -> float:
        """Probability that A succeeds on a seed and B fails."""
        return max(0.0, (self.discordance - self.difference) / 2)

    @property
    def only_b(self) -> float:
        """Probability that B succeeds on a seed and A fails."""
        return max(0.0, (self.discordance + self.difference) / 2)

    @property
    def favour_b(self) -> float:
        """q: the probability that a discordant seed is one where only B succeeds."""
        return min(1.0, self.only_b / self.discordance)


def mcnemar_critical_counts(d: np.ndarray, alpha: float) -> np.ndarray:
    """For each number of discordant seeds `d`: the largest k such that the exact McNemar test
    rejects at level `alpha` when the smaller discordant count is k (it rejects iff
    min(only_a, only_b) <= k; -1: it never rejects). Decided by `mcnemar_exact_pvalue`
    itself, so the plan's test is `compare`'s to the last float; a normal approximation only
    gives the starting point."""
    d = np.atleast_1d(np.asarray(d, np.int64))
    z = sps.norm.isf(alpha / 2)
    k = np.clip(np.floor(d / 2 - z * np.sqrt(d) / 2).astype(np.int64) - 1, -1, d // 2)
    # the p-value grows with the smaller count: move k down while it does not reject, then up
    # while k + 1 does (each pass only over the counts still moving)
    for step in (-1, 1):
        moving = np.arange(d.size)
        while moving.size:
            dm, km = d[moving], k[moving]
            if step < 0:
                moving = moving[(km >= 0) & (mcnemar_exact_pvalue(dm - km, km) > alpha)]
            else:
                ok = (km + 1 <= dm // 2) & (mcnemar_exact_pvalue(dm - km - 1, km + 1) <= alpha)
                moving = moving[ok]
            k[moving] += step
    return k


def _one_sided_power(d: np.ndarray, level: float, q: float) -> np.ndarray:
    """Power at q (> 1/2) of the one-sided randomised Neyman-Pearson test of q = 1/2 at
    `level` with d discordant seeds: reject above c, with probability gamma at c. No test of
    that level on d seeds has more power at q, and it does not fall as d grows (with d + 1
    seeds it could ignore one)."""
    z = sps.norm.isf(level)
    c = np.clip(np.floor(d / 2 + z * np.sqrt(d) / 2).astype(np.int64), 0, d)
    # the smallest c with P(X > c | 1/2) <= level: up while c is too small, then down
    for step in (1, -1):
        moving = np.arange(d.size)
        while moving.size:
            dm, cm = d[moving], c[moving]
            if step > 0:
                moving = moving[sps.binom.sf(cm, dm, 0.5) > level]
            else:
                moving = moving[(cm > 0) & (sps.binom.sf(cm - 1, dm, 0.5) <= level)]
            c[moving] += step
    gamma = (level - sps.binom.sf(c, d, 0.5)) / sps.binom.pmf(c, d, 0.5)
    return sps.binom.sf(c, d, q) + gamma * sps.binom.pmf(c, d, q)


class _Tables:
    """Per number of discordant seeds d = 0, 1, ...: the exact test's rejection probability
    (`reject`) and an upper bound on it that does not fall with d (`bound`), each grown on
    demand (scipy's binomial cdf is slow in bulk).

    The bound: the exact test rejects for B in {only_b >= d - k}, whose probability at
    q = 1/2 is at most alpha / 2, so at q at most the one-sided Neyman-Pearson power at level
    alpha / 2; and for A in {only_b <= k}, whose probability at q > 1/2 is at most
    (4 q (1 - q))^(d/2) times its alpha / 2 at q = 1/2 (the likelihood ratio for
    only_b < d / 2). Their sum, raised to its running maximum over d, does not fall.
    """

    def __init__(self, design: PairedDesign) -> None:
        self.alpha, self.psi = design.alpha, design.discordance
        # the two-sided test is symmetric in A <-> B: its power at q is its power at 1 - q
        self.q = max(design.favour_b, 1 - design.favour_b)
        self._reject, self._bound = np.zeros(0), np.zeros(0)

    @staticmethod
    def _grow(have: np.ndarray, d_max: int) -> np.ndarray | None:
        """The counts to add so that `have` reaches d_max (doubling), or None."""
        if d_max < have.size:
            return None
        return np.arange(have.size, max(d_max + 1, 2 * have.size, 1024))

    def reject(self, d_max: int) -> np.ndarray:
        """The rejection probability for d = 0..d_max at least (the array may be longer)."""
        if (d := self._grow(self._reject, d_max)) is not None:
            q, k = self.q, mcnemar_critical_counts(d, self.alpha)
            # reject iff only_b <= k or only_b >= d - k; the tails are disjoint (k < d / 2)
            r = np.where(k >= 0, sps.binom.cdf(k, d, q) + sps.binom.sf(d - k - 1, d, q), 0.0)
            self._reject = np.concatenate([self._reject, r])
        return self._reject

    def bound(self, d_max: int) -> np.ndarray:
        """The upper bound for d = 0..d_max at least (the array may be longer)."""
        if (d := self._grow(self._bound, d_max)) is not None:
            q, half = self.q, self.alpha / 2
            b = _one_sided_power(d, half, q) + half * (4 * q * (1 - q)) ** (d / 2)
            b = np.maximum.accumulate(np.concatenate([self._bound[-1:], b]))[-d.size :]
            self._bound = np.concatenate([self._bound, b])
        return self._bound

    def floor(self, d_max: int) -> np.ndarray:
        """For d = 0..d_max: the least rejection probability over d..d_max, which does not
        fall with d."""
        return np.minimum.accumulate(self.reject(d_max)[: d_max + 1][::-1])[::-1]

    def expected(self, n: int, values: np.ndarray) -> float:
        """E[values[D]] for D ~ Binomial(n, psi), over the window holding all but ~1e-25."""
        lo, hi = _window(n, self.psi)
        pmf = sps.binom.pmf(np.arange(lo, hi + 1), n, self.psi)
        return float(np.dot(pmf, values[lo : hi + 1]))  # np.dot: matmul may wake BLAS threads

    def powers(self, start: int) -> Iterator[float]:
        """The exact power at n = start, start + 1, ...: the binomial pmf of D steps by
        pmf_{n+1}(d) = (1 - psi) pmf_n(d) + psi pmf_n(d - 1), which costs one pass over it."""
        psi, n = self.psi, start
        lo, hi = _window(n, psi)
        pmf = sps.binom.pmf(np.arange(lo, hi + 1), n, psi)
        while True:
            yield float(np.dot(pmf, self.reject(hi)[lo : hi + 1]))
            pmf = np.concatenate([(1 - psi) * pmf, [0.0]]) + np.concatenate([[0.0], psi * pmf])
            hi, n = hi + 1, n + 1
            if n % 64 == 0:  # drop the tails' negligible ends
                keep = np.nonzero(pmf > 1e-30)[0]
                pmf, lo, hi = pmf[keep[0] : keep[-1] + 1], lo + keep[0], lo + keep[-1]


def _window(n: int, psi: float) -> tuple[int, int]:
    """The discordant counts holding all but ~1e-25 of Binomial(n, psi)."""
    sd = math.sqrt(n * psi * (1 - psi))
    return max(0, math.floor(n * psi - 12 * sd - 12)), min(n, math.ceil(n * psi + 12 * sd + 12))


def _smallest(lo: int, hi: int, reaches: Callable[[int], bool]) -> int:
    """The smallest n in (lo, hi] with reaches(n), for a `reaches` false at lo, true at hi
    and monotone between."""
    while hi - lo > 1:
        mid = (lo + hi) // 2
        lo, hi = (lo, mid) if reaches(mid) else (mid, hi)
    return hi


def mcnemar_power(n: int, design: PairedDesign) -> float:
    """Exact power of the two-sided exact McNemar test at `design.alpha` with `n` paired
    seeds, under `design` (see the module docstring)."""
    if n < 1:
        raise ConfigError(f"seeds must be a positive integer, got {n}")
    tables = _Tables(design)
    return tables.expected(n, tables.reject(_window(n, design.discordance)[1]))


@dataclasses.dataclass(frozen=True)
class PairedPlan:
    """How many paired seeds `design` needs for power `target`. `seeds`: the fewest whose
    power is at least the target (`power` there). `stable_seeds`: the fewest n >= `seeds` from
    which the power is at least the target at every count through 2n (None where 2n would
    pass the cap). `seeds` None: not reached within `cap` seeds (`power_at_cap` says how far
    off)."""

    design: PairedDesign
    target: float
    cap: int
    seeds: int | None
    power: float | None
    stable_seeds: int | None
    power_at_cap: float | None = None


def plan_paired(design: PairedDesign, power: float = 0.8, cap: int = PLAN_CAP) -> PairedPlan:
    """The fewest paired seeds at which the exact McNemar test reaches `power`, searched up to
    `cap` seeds (see `PairedPlan`). Every n is checked from a lower bound on the answer: the
    n below which even `_Tables`' upper bound on the power falls short."""
    _check_open("power", power)
    if cap < 1:
        raise ConfigError(f"cap must be a positive integer, got {cap}")
    psi, tables = design.discordance, _Tables(design)

    def bound_reaches(n: int) -> bool:
        return tables.expected(n, tables.bound(_window(n, psi)[1])) >= power

    lo, hi = 0, 1  # doubling, then bisection: the bound does not fall with n
    while hi < cap and not bound_reaches(hi):
        lo, hi = hi, min(cap, 2 * hi)
    start = _smallest(lo, hi, bound_reaches) if bound_reaches(hi) else cap + 1
    for n, p in zip(range(start, cap + 1), tables.powers(start), strict=False):
        if p >= power:
            return PairedPlan(design, power, cap, n, p, _stays(n, cap, power, tables))
    at_cap = tables.expected(cap, tables.reject(_window(cap, psi)[1]))
    return PairedPlan(design, power, cap, None, None, None, at_cap)


def _stays(first: int, cap: int, power: float, tables: _Tables) -> int | None:
    """The fewest n >= `first` from which the power is at least `power` through 2n.

    A lower bound finds some such n, h: the least rejection probability over d..top
    (`_Tables.floor`) does not fall with d, so its expectation under Binomial(n, psi) does not
    fall with n, and it is at most the power at every n whose discordant counts lie below top
    (all but ~1e-25 of them, up to 2h for top = the window's end at 2h). The exact power at
    every n in [first, h) then says where the last dip below the target is.
    """
    h = first
    while True:  # double h until the bound reaches the target at h
        if 2 * h > cap:
            return None
        floor = tables.floor(_window(2 * h, tables.psi)[1])
        if tables.expected(h, floor) >= power:
            break
        h *= 2

    def reaches(n: int) -> bool:
        return tables.expected(n, floor) >= power

    h = first if reaches(first) else _smallest(first, h, reaches)
    # the bound covers [h, 2h]; the exact power covers [first, h): the first n whose
    # [n, 2n] holds none of the dips below the target there
    powers = zip(range(first, h), tables.powers(first), strict=False)
    dips = [n for n, p in powers if p < power]
    return next(n for n in range(first, h + 1) if not any(n <= d <= 2 * n for d in dips))


@dataclasses.dataclass(frozen=True)
class Pilot:
    """The discordance measured on the common seeds of two earlier reports: `only_a` and
    `only_b` of `seeds` disagree, and A succeeded on `successes_a` of them."""

    seeds: int
    only_a: int
    only_b: int
    successes_a: int
    confidence: float = 0.95

    @classmethod
    def from_comparison(cls, c: Comparison, confidence: float = 0.95) -> Pilot:
        """From a paired `Comparison` of the two reports (`compare_reports`)."""
        if not c.paired:
            raise ConfigError(
                "the reports share no seeds: the discordance needs both policies on the same seeds"
            )
        return cls(c.n_a, int(c.only_a), int(c.only_b), c.successes_a, confidence)

    @classmethod
    def from_decision(cls, report: EvalReport, label: str, confidence: float = 0.95) -> Pilot:
        """From an `eval --compare-with A.json --decide` report (`label`: where it was read):
        the counts of its last look, over the first n seeds of both policies. A's successes
        there are B's (the report's episodes are those seeds) less only-B plus only-A."""
        d = report.decision
        if d is None or not d.looks:
            raise ConfigError(
                f"report {label!r} holds no paired outcomes (no `decision` block: it is not an "
                "eval --compare-with A.json --decide run): give such a report, a comparison "
                "written by compare A.json B.json --out, or --discordance"
            )
        last = d.looks[-1]
        successes_a = report.successes - last.only_b + last.only_a
        if report.n_episodes != last.n or not 0 <= successes_a <= last.n:
            raise ConfigError(
                f"report {label!r}: its last look covers {last.n} seeds (only A {last.only_a}, "
                f"only B {last.only_b}) but it holds {report.n_episodes} episodes with "
                f"{report.successes} successes; the decision does not match its episodes"
            )
        return cls(last.n, last.only_a, last.only_b, successes_a, confidence)

    @property
    def discordance(self) -> float:
        return (self.only_a + self.only_b) / self.seeds

    @property
    def interval(self) -> tuple[float, float]:
        """The discordance's Wilson interval at `confidence`."""
        return wilson_interval(self.only_a + self.only_b, self.seeds, self.confidence)

    def design(
        self, difference: float, rate: float | None = None, alpha: float = 0.05, upper=False
    ) -> PairedDesign:
        """The design at the measured discordance (`upper`: its interval's upper end, which
        needs more seeds, clipped to what the rates allow); `rate` defaults to A's measured
        rate."""
        rate = self.successes_a / self.seeds if rate is None else rate
        psi = self.discordance
        if upper and 0 <= rate <= 1 and 0 <= rate + difference <= 1:
            psi = min(self.interval[1], discordance_range(rate, rate + difference)[1])
        if psi < abs(difference) and 0 <= rate <= 1:
            raise ConfigError(
                f"the reports disagree on {self.only_a + self.only_b} of {self.seeds} common "
                f"seeds (discordance {psi:.3g}), fewer than a difference of {difference:g} "
                "needs: give --discordance instead"
            )
        return PairedDesign(rate, difference, psi, alpha, "reports")


def _pct(x: float) -> str:
    return f"{100 * x:.1f}%"


def format_paired_plan(plan: PairedPlan, pilot: Pilot | None = None, where: str = "") -> str:
    """Human-readable lines: the answer, then what it assumed. `pilot` (with `where`, the
    reports it came from): the measured discordance, and the seeds at its interval's upper
    end."""
    d = plan.design
    test = f"exact McNemar test, two-sided alpha {d.alpha:g}"
    goal = f"B - A = {100 * d.difference:+.1f} points"
    target = f"{100 * plan.target:g}%"
    if plan.seeds is None:
        lines = [
            f"not reached within {plan.cap:,} paired seeds: {goal} is detected with "
            f"{_pct(plan.power_at_cap)} power there (target {target}; {test})"
        ]
    else:
        lines = [
            f"{plan.seeds:,} paired seeds detect {goal} with {_pct(plan.power)} power "
            f"(target {target}; {test})"
        ]
    lines.append(
        f"assumed: A {_pct(d.rate_a)}, B {_pct(d.rate_b)}; discordance {_pct(d.discordance)} "
        f"(only A succeeds on {_pct(d.only_a)} of seeds, only B on {_pct(d.only_b)})"
    )
    if d.source == "stated":
        lines.append("discordance: as stated (--discordance)")
    elif d.source == "independence":
        lines.append(
            "discordance: if outcomes were independent, p_A (1 - p_B) + p_B (1 - p_A); seeds "
            "hard for one policy are usually hard for the other, which lowers it and the seeds "
            "needed: measure it with --from A.json B.json"
        )
    elif pilot is not None:
        low, high = pilot.interval
        lines.append(
            f"discordance: measured on {pilot.seeds:,} common seeds{where} (only A "
            f"{pilot.only_a}, only B {pilot.only_b}): {_pct(pilot.discordance)}, "
            f"{round(100 * pilot.confidence)}% Wilson interval [{_pct(low)}, {_pct(high)}]"
        )
    if plan.seeds is not None:
        if plan.stable_seeds is None:
            lines.append(
                f"whether the power stays >= {target} above {plan.seeds:,} seeds is not checked "
                f"(twice it exceeds the {plan.cap:,}-seed cap)"
            )
        else:
            s = plan.stable_seeds
            lines.append(
                f"the power is >= {target} at every count from {s:,} through {2 * s:,} seeds"
                + (
                    f"; at {s - 1:,} it is below (the exact test's power rises in steps, not "
                    "monotonically)"
                    if s > plan.seeds
                    else ""
                )
            )
    return "\n".join(lines)


def format_interval_plan(
    halfwidth: float, rate: float, confidence: float = 0.95, method: str = "wilson"
) -> str:
    """How many episodes for an interval of `halfwidth` at an observed `rate`, and at 0.5
    (enough whatever the rate): `episodes_for_halfwidth`, in words."""
    n = episodes_for_halfwidth(halfwidth, rate, confidence, method)
    worst = episodes_for_halfwidth(halfwidth, 0.5, confidence, method)
    name = {"wilson": "Wilson", "clopper-pearson": "Clopper-Pearson"}[method]
    lines = [
        f"{n:,} seeds give a {round(100 * confidence)}% {name} interval of half-width <= "
        f"{100 * halfwidth:g} points at an observed rate of {_pct(rate)}"
    ]
    if rate != 0.5:
        lines.append(f"at a rate of 50% (the widest, so enough at any rate): {worst:,} seeds")
    return "\n".join(lines)
