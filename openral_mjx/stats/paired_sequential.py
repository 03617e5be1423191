"""Sequential paired comparison: run policy B on A's seeds in looks until B is better, worse, or
within +-margin of A, with error rates fixed before the first episode.

Per seed the pair of outcomes is discordant ("only A" or "only B" succeeds) with probability
psi, and given that, B's with probability q; the difference of success rates is
delta = rate_B - rate_A = psi (2q - 1). Looks fall after n_1 < ... < n_K = cap seeds, fixed in
advance. At look k the data are the discordant count d_k and B's share w_k of them.

Two exact group-sequential error-spending tests (Lan & DeMets 1983, Biometrika 70: 659-663),
each spending its level alpha_x as the seeds' fraction t_k = n_k / cap grows, per tail half of
f(t_k) (`SPENDING`: O'Brien-Fleming-type or Pocock-type), with boundaries computed exactly by
a dynamic programme over looks (the distribution of the count among runs that have not yet
crossed is convolved with the next look's binomial, and the tail mass that crosses is taken
out), the discrete boundary being the innermost integer whose tail keeps the cumulative
crossing probability within the budget:

* q, conditionally on the discordant counts d_1..d_k: given them, w_k is a binomial random walk
  in d with step probability q, whatever psi. Its test of q = 1/2 (no difference) is the
  decision's test: its type-I error is <= alpha_q given every path of discordant counts, hence
  for every psi. Inverting the tests of every q gives repeated confidence intervals for q.
* psi, from d_k ~ Binomial(n_k, psi): repeated intervals for psi the same way.

The repeated intervals for q hold at every look at once with probability >= 1 - alpha_q, those
for psi with >= 1 - alpha_psi (Jennison & Turnbull 1989, JRSS B 51: 305-361; "Group Sequential
Methods", 2000, ch. 9), so the interval for delta from their product holds at every look at
once, hence at whatever look the run stops and for any stopping rule, with probability
>= 1 - alpha, alpha = alpha_q + alpha_psi. Near delta = 0 the psi part hardly matters (the
interval for delta is psi times that of 2q - 1), so alpha_psi is a small share of alpha.

Decisions, at the first look where one applies: "better" / "worse" when the test of q = 1/2
rejects (equivalently the interval for delta excludes 0), "equivalent" when the interval for
delta lies inside (-margin, margin), else at the cap "inconclusive". So: P(better or worse
when delta = 0) <= alpha_q; P(equivalent when |delta| >= margin) <= alpha; P(the other
direction) <= alpha_q / 2.
"""

from __future__ import annotations

import dataclasses
import functools
import itertools
from collections.abc import Sequence

import numpy as np
from scipy import signal
from scipy import stats as sps

from openral_mjx.core.errors import ConfigError, unknown

SPENDING = ("obrien-fleming", "pocock")
DECISIONS = ("better", "worse", "equivalent", "inconclusive")
PSI_SHARE = 0.1  # share of alpha spent on the discordance's intervals
_TOL = 1e-12  # budgets are met up to float rounding of the crossing masses


@functools.lru_cache(maxsize=4096)
def _pmf(n: int, p: float) -> np.ndarray:
    """Binomial(n, p) probabilities of 0..n (cached: the same look sizes recur)."""
    out = sps.binom.pmf(np.arange(n + 1), n, p)
    out.flags.writeable = False
    return out


def add_binomial(mass: np.ndarray, trials: int, p: float) -> np.ndarray:
    """The distribution of a count (`mass[i]`: P(count = i), possibly sub-stochastic: runs
    that crossed a boundary taken out) after `trials` more Bernoulli(`p`) trials: `mass`
    convolved with Binomial(`trials`, `p`), a new array. The step of every dynamic programme
    over looks here and in `decide_planning`."""
    if not trials:
        return mass.copy()
    return np.clip(signal.convolve(mass, _pmf(trials, p)), 0.0, None)


def spent(t: float, alpha: float, spending: str) -> float:
    """Two-sided alpha spent by information fraction `t` in [0, 1] (f(1) = alpha).

    O'Brien-Fleming-type: 2 (1 - Phi(z_{1 - alpha/2} / sqrt(t))), little early, nearly all at
    the end (the cap costs little over a fixed-size test); Pocock-type: alpha ln(1 + (e - 1) t),
    more early (earlier stops for large differences, a larger cap for the same power).
    """
    if spending not in SPENDING:
        raise unknown("spending function", spending, SPENDING)
    if t <= 0:
        return 0.0
    if t >= 1:
        return alpha
    if spending == "pocock":
        return float(alpha * np.log1p((np.e - 1) * t))
    return float(2 * sps.norm.sf(sps.norm.isf(alpha / 2) / np.sqrt(t)))


def boundaries(trials: Sequence[int], p: float, budgets: Sequence[float]) -> list[tuple[int, int]]:
    """(lower, upper) per look for a binomial count over cumulative `trials` at success
    probability `p`: the count crosses at look j if it is <= lower or >= upper there (and did
    not cross before). Each is the innermost integer keeping the probability of crossing that
    side by look j within `budgets[j]` (cumulative, per side)."""
    out: list[tuple[int, int]] = []
    mass, prev = np.ones(1), 0
    used_lo = used_hi = 0.0
    for m, budget in zip(trials, budgets, strict=True):
        mass, prev = add_binomial(mass, m - prev, p), m
        hi_tail = np.append(np.cumsum(mass[::-1])[::-1], 0.0)  # hi_tail[u] = P(count >= u)
        lo_tail = np.cumsum(mass)  # lo_tail[l] = P(count <= l)
        upper = int(np.argmax(used_hi + hi_tail <= budget + _TOL))
        ok = np.nonzero(used_lo + lo_tail <= budget + _TOL)[0]
        lower = int(ok[-1]) if ok.size else -1
        lower = min(lower, upper - 1)
        used_hi += float(hi_tail[upper])
        used_lo += float(lo_tail[lower]) if lower >= 0 else 0.0
        mass[upper:] = 0.0
        mass[: lower + 1] = 0.0
        out.append((lower, upper))
    return out


def crossing(
    trials: Sequence[int], bounds: Sequence[tuple[int, int]], p: float
) -> tuple[float, float]:
    """Probabilities at success probability `p` that the count first crosses `bounds` below,
    and above (exact, by the same dynamic programme)."""
    mass, prev = np.ones(1), 0
    below = above = 0.0
    for m, (lower, upper) in zip(trials, bounds, strict=True):
        mass, prev = add_binomial(mass, m - prev, p), m
        above += float(mass[upper:].sum())
        below += float(mass[: lower + 1].sum()) if lower >= 0 else 0.0
        mass[upper:] = 0.0
        mass[: max(lower + 1, 0)] = 0.0
    return below, above


def _bisect(crossed, lo: float = 0.0, hi: float = 1.0) -> float:
    """The switch point of a predicate True at `lo` and False at `hi`, to 1e-10."""
    for _ in range(34):
        mid = (lo + hi) / 2
        lo, hi = (mid, hi) if crossed(mid) else (lo, mid)
    return (lo + hi) / 2


def repeated_interval(
    trials: Sequence[int], count: int, budgets: Sequence[float], which: str = "both"
) -> tuple[float, float]:
    """The repeated confidence interval for the success probability at the last look of
    `trials`, after `count` successes: the p whose own boundaries (`boundaries`, same budgets)
    `count` does not cross there. Endpoints by bisection to 1e-10 (`which`: "low" or "high"
    computes one end only and returns the trivial 0 or 1 for the other)."""
    trials, n = tuple(int(t) for t in trials), int(trials[-1])

    def last(p: float) -> tuple[int, int]:
        return boundaries(trials, p, budgets)[-1]

    low = high = None
    if which in ("both", "low"):
        low = 0.0 if count == 0 else _bisect(lambda p: count >= last(p)[1])
    if which in ("both", "high"):
        high = 1.0 if count == n else 1.0 - _bisect(lambda p: count <= last(1 - p)[0])
    return (0.0 if low is None else low), (1.0 if high is None else high)


@dataclasses.dataclass(frozen=True)
class Look:
    """One look of a sequential comparison: `n` seeds, the discordant ones split `only_a` /
    `only_b`; the test of no difference stops above if `only_b >= upper`, below if
    `only_b <= lower`; the decision taken here (None: go on); [`ci_low`, `ci_high`] the
    repeated interval for rate_B - rate_A (computed where asked: at the deciding look)."""

    n: int
    only_a: int
    only_b: int
    lower: int
    upper: int
    decision: str | None
    ci_low: float | None = None
    ci_high: float | None = None


@dataclasses.dataclass(frozen=True)
class PairedDecisionDesign:
    """The sequential paired comparison's design (see module): looks at cumulative seed
    counts `looks`, overall error rate `alpha`, equivalence `margin` (None: no equivalence
    decision), spending function `spending`."""

    looks: tuple[int, ...]
    alpha: float = 0.05
    margin: float | None = None
    spending: str = "obrien-fleming"

    def __post_init__(self) -> None:
        looks = tuple(int(n) for n in self.looks)
        if not looks or looks[0] < 1 or any(b <= a for a, b in itertools.pairwise(looks)):
            raise ConfigError(f"looks must be increasing positive seed counts, got {list(looks)}")
        object.__setattr__(self, "looks", looks)
        if not 0 < self.alpha < 1:
            raise ConfigError(f"alpha must lie in (0, 1), got {self.alpha}")
        if self.margin is not None and not 0 < self.margin < 1:
            raise ConfigError(
                f"margin must lie in (0, 1) (a difference of success rates), got {self.margin}"
            )
        if self.spending not in SPENDING:
            raise unknown("spending function", self.spending, SPENDING)

    @classmethod
    def in_chunks(
        cls,
        chunk: int,
        cap: int,
        alpha: float = 0.05,
        margin: float | None = None,
        spending: str = "obrien-fleming",
    ) -> PairedDecisionDesign:
        """A look after every `chunk` seeds up to `cap` (the last chunk may be partial)."""
        if chunk < 1 or cap < 1:
            raise ConfigError(f"chunk and cap must be positive seed counts, got {chunk}, {cap}")
        return cls((*range(chunk, cap, chunk), cap), alpha, margin, spending)

    @property
    def cap(self) -> int:
        return self.looks[-1]

    @property
    def alpha_q(self) -> float:
        """Level of the test of no difference (on B's share of the discordant seeds)."""
        return (1 - PSI_SHARE) * self.alpha

    @property
    def alpha_psi(self) -> float:
        """Level spent on the discordance's repeated intervals."""
        return PSI_SHARE * self.alpha

    def budgets(self, level: float, k: int) -> tuple[float, ...]:
        """Cumulative per-side budgets of a test at `level` for looks 0..k."""
        return tuple(spent(n / self.cap, level, self.spending) / 2 for n in self.looks[: k + 1])

    def test_bounds(self, discordant: Sequence[int]) -> tuple[int, int]:
        """(lower, upper) on `only_b` at look len(discordant) - 1 for the test of no
        difference, given the discordant counts at every look so far."""
        k = len(discordant) - 1
        return boundaries(tuple(discordant), 0.5, self.budgets(self.alpha_q, k))[-1]

    def interval(self, discordant: Sequence[int], only_b: int) -> tuple[float, float]:
        """Repeated interval for rate_B - rate_A at look len(discordant) - 1 (see module)."""
        k = len(discordant) - 1
        q_low, q_high = (
            repeated_interval(tuple(discordant), only_b, self.budgets(self.alpha_q, k))
            if discordant[-1]
            else (0.0, 1.0)
        )
        psi_low, psi_high = repeated_interval(
            self.looks[: k + 1], discordant[-1], self.budgets(self.alpha_psi, k)
        )
        g_low, g_high = 2 * q_low - 1, 2 * q_high - 1
        low = g_low * (psi_low if g_low >= 0 else psi_high)
        high = g_high * (psi_high if g_high >= 0 else psi_low)
        return low, high

    def within_margin(self, discordant: Sequence[int], only_b: int) -> bool:
        """Whether `interval` lies inside (-margin, margin), without computing all of it:
        |delta| <= psi_high settles it when psi_high < margin; else delta_high < margin iff
        q_high < q* = (1 + margin / psi_high) / 2, i.e. `only_b` crosses the lower boundary
        of q* (and symmetrically below)."""
        if self.margin is None:
            return False
        k = len(discordant) - 1
        psi_budgets = self.budgets(self.alpha_psi, k)
        psi_high = repeated_interval(self.looks[: k + 1], discordant[-1], psi_budgets, "high")[1]
        if psi_high < self.margin:
            return True
        q_star = (1 + self.margin / psi_high) / 2
        if q_star >= 1:  # (cannot happen here: psi_high >= margin)
            return True
        path, budgets = tuple(discordant), self.budgets(self.alpha_q, k)
        below = only_b <= boundaries(path, q_star, budgets)[-1][0]
        return below and only_b >= boundaries(path, 1 - q_star, budgets)[-1][1]

    def look(
        self, k: int, only_a: Sequence[int], only_b: Sequence[int], interval: bool = False
    ) -> Look:
        """Look `k` given the cumulative discordant counts of looks 0..k; the interval is
        computed where the look decides, or where `interval` asks for it."""
        discordant = [a + b for a, b in zip(only_a[: k + 1], only_b[: k + 1], strict=True)]
        lower, upper = self.test_bounds(discordant)
        b = int(only_b[k])
        decision = None
        if b >= upper:
            decision = "better"
        elif b <= lower:
            decision = "worse"
        elif self.within_margin(discordant, b):
            decision = "equivalent"
        elif k == len(self.looks) - 1:
            decision = "inconclusive"
        low = high = None
        if decision is not None or interval:
            low, high = self.interval(discordant, b)
        return Look(self.looks[k], int(only_a[k]), b, lower, upper, decision, low, high)

    def run(self, success_a: np.ndarray, success_b: np.ndarray) -> list[Look]:
        """The looks of the rule on per-seed outcomes (element i: seed i of both), up to the
        one that decides (the outcomes must reach it)."""
        a, b = np.asarray(success_a, bool), np.asarray(success_b, bool)
        only_a, only_b, looks = [], [], []
        for k, n in enumerate(self.looks):
            if n > min(a.size, b.size):
                raise ValueError(f"outcomes of {min(a.size, b.size)} seeds do not reach look {n}")
            only_a.append(int((a[:n] & ~b[:n]).sum()))
            only_b.append(int((~a[:n] & b[:n]).sum()))
            looks.append(self.look(k, only_a, only_b))
            if looks[-1].decision is not None:
                break
        return looks

    def describe(self) -> str:
        margin = "none" if self.margin is None else f"+-{self.margin:g}"
        return (
            f"group-sequential paired comparison: looks at {len(self.looks)} seed counts up to "
            f"{self.cap}; exact conditional test of no difference on the discordant seeds at "
            f"level {self.alpha_q:.3g} ({self.spending} spending over seeds); repeated "
            f"interval for B - A with simultaneous coverage >= {1 - self.alpha:.3g}; "
            f"equivalence margin {margin}"
        )


__all__ = [
    "DECISIONS",
    "PSI_SHARE",
    "SPENDING",
    "Look",
    "PairedDecisionDesign",
    "add_binomial",
    "boundaries",
    "crossing",
    "repeated_interval",
    "spent",
]
