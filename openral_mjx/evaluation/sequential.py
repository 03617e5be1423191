"""Sequential runs inside an evaluation: the runner's stopping rules for a target interval
half-width (`SequentialRule`, on the exact group-sequential design of `stats.sequential`) and
for a paired comparison with an earlier report (`PairedRule`, on `stats.paired_sequential`)."""

from __future__ import annotations

import dataclasses
from collections.abc import Mapping
from typing import Any

import numpy as np

from openral_mjx.core.errors import ConfigError
from openral_mjx.report import DecisionInfo, DecisionLook, EvalReport
from openral_mjx.runner import check_counts
from openral_mjx.stats.paired_sequential import Look, PairedDecisionDesign
from openral_mjx.stats.sequential import SequentialDesign, sufficient_episodes


class SequentialRule:
    """The runner's `until` for a sequential run: stop once the design says so.

    The design's looks fall after each of the runner's chunks. The runner fixes the chunk
    size (devices, memory) before any episode runs, and the first look reveals it, so the
    design is built then: it still depends on no outcome.
    """

    def __init__(self, halfwidth: float, max_episodes: int) -> None:
        self.halfwidth, self.max_episodes = halfwidth, max_episodes
        self._design: SequentialDesign | None = None

    @property
    def design(self) -> SequentialDesign:
        if self._design is None:
            raise RuntimeError("the sequential design is fixed at the first look")
        return self._design

    def fix(self, chunk: int) -> None:
        """Fix the design for looks every `chunk` episodes now (a resumed run: its first
        look comes after the chunks of the run it resumes)."""
        self._design = SequentialDesign.in_chunks(chunk, self.halfwidth, self.max_episodes)

    def __call__(self, arrays: Mapping[str, Any]) -> bool:
        n = len(arrays["success"])
        if self._design is None:
            self._design = SequentialDesign.in_chunks(n, self.halfwidth, self.max_episodes)
        return self._design.stops(self._design.looks.index(n), int(arrays["success"].sum()))


def sequential_rule(
    n_envs: int, n_episodes: int | None, target: float | None, max_episodes: int | None
) -> SequentialRule | None:
    """The stopping rule for `target_halfwidth`, or None for a fixed episode count."""
    if target is None:
        if max_episodes is not None:
            raise ConfigError(
                "max_episodes caps a sequential run: give target_halfwidth too "
                "(or n_episodes for a fixed count)"
            )
        return None
    if n_episodes is not None:
        raise ConfigError(
            "n_episodes and target_halfwidth exclude each other: a sequential run decides "
            "how many episodes it needs (cap it with max_episodes)"
        )
    if not 0 < target < 0.5:
        raise ConfigError(f"target_halfwidth must lie in (0, 0.5), got {target}")
    if max_episodes is not None and max_episodes < 1:
        raise ConfigError(f"max_episodes must be a positive integer, got {max_episodes}")
    check_counts(n_envs, 1, 1)
    return SequentialRule(target, max_episodes or sufficient_episodes(target))


class PairedRule:
    """The runner's `until` for `--decide`: B's outcomes on the finished prefix of seeds
    against A's on the same seeds (`baseline[i]`: A's outcome on the run's i-th seed), looked
    at after every chunk of the runner's, stopped at the first look that decides.

    As `SequentialRule`, the design is fixed at the first look, when the runner's chunk size
    is known and no outcome has been seen. Only the first `n` seeds, all finished, enter a
    look (the runner's prefix rule), so a seed that happened to finish early never does.
    A run interrupted between looks resumes with `resume`: the design fixed at the
    interrupted run's chunk and its looks replayed, so the rest falls where it would have.
    """

    def __init__(
        self,
        baseline: np.ndarray,
        label: str,
        baseline_policy: str,
        alpha: float = 0.05,
        margin: float | None = None,
        spending: str = "obrien-fleming",
    ) -> None:
        self.baseline = np.asarray(baseline, bool)
        self.label, self.baseline_policy = label, baseline_policy
        self.alpha, self.margin, self.spending = alpha, margin, spending
        self.looks: list[Look] = []
        self._design: PairedDecisionDesign | None = None
        # checked now, before anything runs (the chunk is a placeholder)
        PairedDecisionDesign.in_chunks(1, self.cap, alpha, margin, spending)

    @property
    def cap(self) -> int:
        return int(self.baseline.size)

    @property
    def design(self) -> PairedDecisionDesign:
        if self._design is None:
            raise RuntimeError("the paired design is fixed at the first look")
        return self._design

    def fix(self, chunk: int) -> None:
        """Fix the design for looks every `chunk` seeds now (see `resume`)."""
        self._design = PairedDecisionDesign.in_chunks(
            chunk, self.cap, self.alpha, self.margin, self.spending
        )

    def resume(self, decision: DecisionInfo, success: np.ndarray) -> None:
        """Pick up the undecided run whose partial report holds `decision` and B's outcomes
        `success` on its first seeds: its design (checked to be this rule's) and its
        looks, replayed on those outcomes (checked to be the report's own). `ConfigError`
        where they differ, or where the report's looks already decided."""
        mine = (self.label, self.cap, self.alpha, self.margin, self.spending)
        theirs = (decision.baseline, decision.cap, decision.alpha, decision.margin)
        if mine != (*theirs, decision.spending):
            raise ConfigError(
                f"--resume: the partial report decided against {decision.baseline!r} with cap "
                f"{decision.cap}, alpha {decision.alpha:g}, margin {decision.margin}, spending "
                f"{decision.spending}; this run: {self.label!r}, {self.cap}, {self.alpha:g}, "
                f"{self.margin}, {self.spending}"
            )
        self.fix(decision.chunk)
        self.looks = []
        ns = [n for n in self.design.looks if n <= success.size]
        if ns[-1:] != [success.size] or decision.decision != "undecided":
            raise ConfigError(
                f"--resume: the partial report is not an undecided --decide run stopped at a look "
                f"(decision {decision.decision!r}, {success.size} episodes, looks every "
                f"{decision.chunk})"
            )
        for n in ns:
            self({"success": success[:n]})
        replayed = [DecisionLook(x.n, x.only_a, x.only_b, x.lower, x.upper) for x in self.looks]
        if replayed != decision.looks or any(x.decision is not None for x in self.looks):
            raise ConfigError(
                "--resume: the partial report's looks are not those its episodes give against "
                f"{self.label!r} (was A's report changed?)"
            )

    def __call__(self, arrays: Mapping[str, Any]) -> bool:
        b = np.asarray(arrays["success"], bool)
        n = b.size
        if self._design is None:
            self.fix(n)
        assert self._design is not None
        k = self._design.looks.index(n)
        a = self.baseline[:n]
        ns = self._design.looks[: k + 1]
        only_a = [int((a[:m] & ~b[:m]).sum()) for m in ns]
        only_b = [int((~a[:m] & b[:m]).sum()) for m in ns]
        look = self._design.look(k, only_a, only_b)
        self.looks = [*self.looks[:k], look]
        return look.decision is not None

    def info(self) -> DecisionInfo:
        """The report's `decision` block: after the run stopped, or after an interrupt between
        looks ("undecided"; the repeated interval holds at every look, so at this one too)."""
        last = self.looks[-1]
        design = self.design
        if last.decision is None:
            k = len(self.looks) - 1
            only_a = [x.only_a for x in self.looks]
            last = design.look(k, only_a, [x.only_b for x in self.looks], interval=True)
            last = dataclasses.replace(last, decision="undecided")
        assert last.decision is not None and last.ci_low is not None and last.ci_high is not None
        return DecisionInfo(
            baseline=self.label,
            baseline_policy=self.baseline_policy,
            rule=design.describe(),
            alpha=design.alpha,
            margin=design.margin,
            spending=design.spending,
            chunk=design.looks[0],
            cap=design.cap,
            looks=[DecisionLook(x.n, x.only_a, x.only_b, x.lower, x.upper) for x in self.looks],
            decision=last.decision,
            difference=(last.only_b - last.only_a) / last.n,
            ci_low=last.ci_low,
            ci_high=last.ci_high,
        )


def paired_rule(
    baseline: EvalReport,
    label: str,
    seed: int,
    n_episodes: int | None,
    alpha: float,
    margin: float | None,
    spending: str,
) -> PairedRule:
    """The `--decide` rule against report `baseline` (read from `label`): A's outcomes on
    seeds `seed`, `seed + 1`, ... up to the cap, `n_episodes` or (default) as far as A's
    report has every seed. `ConfigError` if A lacks a seed the cap needs."""
    outcomes = {int(e.metadata["seed"]): bool(e.success) for e in baseline.episodes}
    have = 0
    while seed + have in outcomes:
        have += 1
    if have == 0:
        raise ConfigError(
            f"--decide: report {label!r} has no episode of seed {seed} (--seed); it has seeds "
            f"{_seed_span(outcomes)}: give --seed inside them"
        )
    cap = have if n_episodes is None else n_episodes
    if cap > have:
        raise ConfigError(
            f"--decide: --n-episodes {cap} needs A's outcomes on seeds {seed}..{seed + cap - 1}, "
            f"but report {label!r} has seeds {_seed_span(outcomes)}: give --n-episodes <= "
            f"{have}, or rerun A on {cap} seeds"
        )
    if cap < 1:
        raise ConfigError(f"--n-episodes must be a positive integer, got {cap}")
    return PairedRule(
        np.array([outcomes[seed + i] for i in range(cap)]),
        label,
        baseline.policy,
        alpha,
        margin,
        spending,
    )


def _seed_span(outcomes: Mapping[int, bool]) -> str:
    """E.g. "0..511" or "0..99 and 12 others": A's seeds, for an error message."""
    seeds = sorted(outcomes)
    run = 1
    while run < len(seeds) and seeds[run] == seeds[0] + run:
        run += 1
    rest = f" and {len(seeds) - run} others" if run < len(seeds) else ""
    return f"{seeds[0]}..{seeds[run - 1]}{rest}"
