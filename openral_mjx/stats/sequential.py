"""Sequential estimation: roll out chunks of seeds until the success-rate interval is narrow.

The design is fixed before the first episode: a look after every chunk, at cumulative episode
counts n_1 < ... < n_K = max_episodes, and the rule "stop at the first look where the fixed-n
Clopper-Pearson half-width of the successes so far is at most the target, else at n_K".

Reporting a fixed-n interval at such a data-dependent stopping time over-states confidence:
runs whose observed rate drifted away from 1/2 stop early, so the outcomes that end the run are
not a fixed-n sample. Computed exactly for chunks of 1,024 and a 0.01 target, a nominal 95%
Clopper-Pearson interval (>= 95% at any fixed n) covers only 94.0% at some rates under this
rule, and Wilson 93.4%; the tests show the same for small designs. The report gives instead the
exact confidence interval for this group-sequential design (Jennison & Turnbull 1983,
Technometrics 25: 49-58; "Group Sequential Methods", 2000, ch. 8). Outcomes (look, successes)
are ranked in the stagewise ordering: one that stopped at an earlier look above the
continuation region ranks above every later outcome, one below it below them; at the same look
more successes rank higher. The interval holds every rate at which neither tail probability of
the observed outcome in that ordering is below (1 - confidence) / 2. For one look this is
Clopper-Pearson; like it, its coverage is at least the nominal level at every rate, here under
the stopping rule; and where stopping earlier was unlikely it coincides with Clopper-Pearson.

The tail probabilities come from an exact dynamic programme over looks: the distribution of
successes among runs still going is convolved with the next chunk's binomial, and the mass
that stops is set aside.
"""

from __future__ import annotations

import dataclasses
import itertools
from typing import Any

import numpy as np
from scipy import optimize, signal
from scipy import stats as sps

from openral_mjx.core.errors import ConfigError
from openral_mjx.stats.intervals import (
    check_confidence,
    clopper_pearson_interval,
    episodes_for_halfwidth,
)

RULE = (
    "stop at the first look (after each chunk) whose fixed-n Clopper-Pearson half-width is <= "
    "target_halfwidth, else at max_episodes; interval: exact for this group-sequential design "
    "(stagewise ordering), coverage >= confidence under this rule"
)


def _halfwidth(successes: int, n: int, confidence: float) -> float:
    low, high = clopper_pearson_interval(successes, n, confidence)
    return (high - low) / 2


def _bounds(n: int, halfwidth: float, confidence: float, final: bool) -> tuple[int, int]:
    """(lower, upper): the run stops at this look iff successes <= lower or >= upper.

    The Clopper-Pearson half-width is symmetric in k <-> n - k and largest at n/2, so the
    continuation region is the integer interval (lower, upper) around n/2.
    """
    mid = n // 2
    if final or _halfwidth(mid, n, confidence) <= halfwidth:
        return mid, mid + 1  # every outcome stops
    if _halfwidth(n, n, confidence) > halfwidth:
        return -1, n + 1  # none does
    lo, hi = n - mid, n  # smallest k in [ceil(n/2), n] with half-width <= target
    while lo < hi:
        k = (lo + hi) // 2
        lo, hi = (lo, k) if _halfwidth(k, n, confidence) <= halfwidth else (k + 1, hi)
    return n - lo, lo


def sufficient_episodes(halfwidth: float, confidence: float = 0.95) -> int:
    """Fewest episodes at which every outcome meets the target (the Clopper-Pearson half-width
    is largest at n/2 successes): the default cap, which a run never reaches unmet."""
    n = episodes_for_halfwidth(halfwidth, 0.5, confidence, "clopper-pearson")
    while _halfwidth(n // 2, n, confidence) > halfwidth:
        n += 1
    while n > 1 and _halfwidth((n - 1) // 2, n - 1, confidence) <= halfwidth:
        n -= 1
    return n


@dataclasses.dataclass(frozen=True)
class SequentialDesign:
    """Looks at cumulative episode counts `looks`; stop rule and exact interval (see module).

    Looks are indexed from 0. `lower[j]`/`upper[j]`: stop at look j iff successes <= lower[j]
    or >= upper[j] (every outcome stops at the last look).
    """

    looks: tuple[int, ...]
    halfwidth: float
    confidence: float = 0.95
    lower: tuple[int, ...] = dataclasses.field(init=False, repr=False)
    upper: tuple[int, ...] = dataclasses.field(init=False, repr=False)

    def __post_init__(self) -> None:
        if not 0 < self.halfwidth < 0.5:
            raise ConfigError(f"target_halfwidth must lie in (0, 0.5), got {self.halfwidth}")
        check_confidence(self.confidence)
        looks = tuple(int(n) for n in self.looks)
        if not looks or looks[0] < 1 or any(b <= a for a, b in itertools.pairwise(looks)):
            raise ConfigError(f"looks must be increasing positive counts, got {list(looks)}")
        bounds = [
            _bounds(n, self.halfwidth, self.confidence, j == len(looks) - 1)
            for j, n in enumerate(looks)
        ]
        object.__setattr__(self, "looks", looks)
        object.__setattr__(self, "lower", tuple(b[0] for b in bounds))
        object.__setattr__(self, "upper", tuple(b[1] for b in bounds))

    @classmethod
    def in_chunks(
        cls,
        chunk: int,
        halfwidth: float,
        max_episodes: int | None = None,
        confidence: float = 0.95,
    ) -> SequentialDesign:
        """A look after every `chunk` episodes, up to `max_episodes` (the last chunk may be
        partial). The default cap is `sufficient_episodes`, at which every outcome meets the
        target, so by default the cap never ends a run before the target."""
        if chunk < 1:
            raise ConfigError(f"n_envs must be a positive integer, got {chunk}")
        if not 0 < halfwidth < 0.5:
            raise ConfigError(f"target_halfwidth must lie in (0, 0.5), got {halfwidth}")
        if max_episodes is None:
            max_episodes = sufficient_episodes(halfwidth, confidence)
        if max_episodes < 1:
            raise ConfigError(f"max_episodes must be a positive integer, got {max_episodes}")
        looks = (*range(chunk, max_episodes, chunk), max_episodes)
        return cls(looks, halfwidth, confidence)

    @property
    def max_episodes(self) -> int:
        return self.looks[-1]

    def stops(self, look: int, successes: Any) -> Any:
        """Whether the run ends at `look` with `successes` so far (broadcasts over arrays)."""
        out = (np.asarray(successes) <= self.lower[look]) | (
            np.asarray(successes) >= self.upper[look]
        )
        return bool(out) if out.ndim == 0 else out

    def meets_target(self, look: int, successes: int) -> bool:
        """Whether the fixed-n half-width at `look` is within the target (at the last look
        the run stops either way: this tells the target from the cap)."""
        n = self.looks[look]
        return _halfwidth(successes, n, self.confidence) <= self.halfwidth

    def reached(self, rate: float, last: int) -> list[tuple[int, np.ndarray]]:
        """For looks 0..`last`: (offset, mass) with mass[i] the probability at `rate` that the
        run reaches the look (has not stopped before) with offset + i successes."""
        out: list[tuple[int, np.ndarray]] = []
        offset, mass = 0, np.ones(1)
        pmfs: dict[int, np.ndarray] = {}
        prev = 0
        for j in range(last + 1):
            size = self.looks[j] - prev
            prev = self.looks[j]
            if size not in pmfs:
                pmfs[size] = sps.binom.pmf(np.arange(size + 1), size, rate)
            mass = np.clip(signal.convolve(mass, pmfs[size]), 0.0, None)
            keep = np.nonzero(mass > 1e-17 * mass.max())[0] if mass.max() > 0 else [0]
            offset, mass = offset + keep[0], mass[keep[0] : keep[-1] + 1]
            out.append((offset, mass))
            ks = offset + np.arange(mass.size)
            mass = np.where((ks > self.lower[j]) & (ks < self.upper[j]), mass, 0.0)
        return out

    def stop_probabilities(self, rate: float) -> list[tuple[int, np.ndarray]]:
        """For every look: (offset, p) with p[i] the probability at `rate` that the run stops
        at that look with offset + i successes (all looks' p sum to 1)."""
        out = []
        for j, (offset, mass) in enumerate(self.reached(rate, len(self.looks) - 1)):
            ks = offset + np.arange(mass.size)
            out.append((offset, np.where(self.stops(j, ks), mass, 0.0)))
        return out

    def tail_probabilities(self, rate: float, look: int, successes: int) -> tuple[float, float]:
        """P(outcome ranks >= observed), P(outcome ranks <= observed) at `rate`, in the
        stagewise ordering (see module docstring)."""
        above = below = 0.0
        reached = self.reached(rate, look)
        for j, (offset, mass) in enumerate(reached[:-1]):
            ks = offset + np.arange(mass.size)
            above += float(mass[ks >= self.upper[j]].sum())
            below += float(mass[ks <= self.lower[j]].sum())
        offset, mass = reached[-1]
        ks = offset + np.arange(mass.size)
        stop = self.stops(look, ks)
        going = float(mass[~stop].sum())  # runs that go on rank above a low stop, below a high
        high_stop = successes >= self.upper[look]
        above += float(mass[stop & (ks >= successes)].sum()) + (0.0 if high_stop else going)
        below += float(mass[stop & (ks <= successes)].sum()) + (going if high_stop else 0.0)
        return above, below

    def interval(self, look: int, successes: int) -> tuple[float, float]:
        """The exact interval after stopping at `look` with `successes` (see module)."""
        if not 0 <= successes <= self.looks[look] or not self.stops(look, successes):
            raise ValueError(f"the design does not stop at look {look} with {successes} successes")
        tail = (1 - self.confidence) / 2

        def bound(side: int) -> float:
            edge = 0.0 if side == 0 else 1.0
            if self.tail_probabilities(edge, look, successes)[side] > tail:
                return edge  # the observed outcome is the extreme one
            return optimize.brentq(
                lambda r: self.tail_probabilities(r, look, successes)[side] - tail,
                0.0,
                1.0,
                xtol=1e-12,
            )

        return bound(0), bound(1)


__all__ = ["RULE", "SequentialDesign", "sufficient_episodes"]
