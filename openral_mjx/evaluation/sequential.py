"""Sequential estimation inside an evaluation: the runner's stopping rule for a target
interval half-width, built on the exact group-sequential design of `stats.sequential`."""

from __future__ import annotations

from collections.abc import Mapping
from typing import Any

from openral_mjx.core.errors import ConfigError
from openral_mjx.runner import check_counts
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
