"""`RunSpec`: every setting of one evaluation run, checked once, passed down whole.

The CLI (`eval`), `run_evaluation` and `evaluate_suite` used to re-list these settings as
keyword arguments, and the lists drifted (a suite silently dropped `batching`). One frozen
object means a setting is either carried to the runner or refused where it does not apply
(`for_suite`), never dropped on the way.
"""

from __future__ import annotations

import dataclasses

from openral_mjx.core.errors import ConfigError
from openral_mjx.evaluation.sequential import SequentialRule, sequential_rule
from openral_mjx.physics.base import check_warp_graphs
from openral_mjx.runner import MAX_STEPS, check_batching, check_counts, check_seeds

FACTOR_BINS = 5  # equal-count bins per episode factor in a report's breakdown
MAX_FACTOR_BINS = 1000
# Upper bounds of the build settings, refused before anything is built: threads each start an
# OS thread, a contact buffer is allocated per env, and no host has more devices.
MAX_SETTING = {
    "devices": 4096,
    "threads": 4096,
    "contacts_per_env": 65536,
    "ccd_contacts_per_env": 65536,
}


@dataclasses.dataclass(frozen=True)
class RunSpec:
    """What to build (`backend`, `n_envs`, `threads`, the `warp` buffers and graphs,
    `devices`) and how
    to run it (episode counts, sequential target, seeds, steps, batching, breakdown bins);
    see `run_evaluation` for each. Construction raises `ConfigError` naming the first bad
    value, so a spec that exists is valid (the backend-specific batching check waits for a
    named backend: `auto` is resolved when the scene is built)."""

    n_envs: int = 1024
    n_episodes: int | None = None
    target_halfwidth: float | None = None
    max_episodes: int | None = None
    max_steps: int | None = None
    seed: int = 0
    factor_bins: int = FACTOR_BINS
    batching: str = "auto"
    refill_every: int = 1
    step_rewards: bool = False
    backend: str = "auto"
    threads: int | None = None
    contacts_per_env: int | None = None
    ccd_contacts_per_env: int | None = None
    warp_graphs: str | None = None
    devices: int | None = None
    command: str = ""

    def __post_init__(self) -> None:
        self._counts()
        if self.factor_bins < 1:
            raise ConfigError(f"factor_bins must be a positive integer, got {self.factor_bins}")
        if self.factor_bins > MAX_FACTOR_BINS:
            raise ConfigError(
                f"factor_bins must be at most {MAX_FACTOR_BINS}, got {self.factor_bins}"
            )
        if self.refill_every > MAX_STEPS:
            raise ConfigError(
                f"refill_every must be at most {MAX_STEPS:,}, got {self.refill_every}"
            )
        check_warp_graphs(self.warp_graphs)
        for name in MAX_SETTING:
            value = getattr(self, name)
            if value is not None and value < 1:
                raise ConfigError(f"{name} must be >= 1, got {value}")
            if value is not None and value > MAX_SETTING[name]:
                raise ConfigError(f"{name} must be at most {MAX_SETTING[name]:,}, got {value}")
        backend = "c" if self.backend == "auto" else self.backend  # auto may resolve to c
        check_batching(self.batching, backend, self.refill_every, traces=self.step_rewards)

    def _counts(self) -> tuple[SequentialRule | None, int]:
        rule = sequential_rule(
            self.n_envs, self.n_episodes, self.target_halfwidth, self.max_episodes
        )
        episodes = self.n_envs if self.n_episodes is None else self.n_episodes
        if rule is not None:
            episodes = rule.max_episodes
        check_counts(self.n_envs, episodes, 1 if self.max_steps is None else self.max_steps)
        check_seeds(self.seed, episodes)
        return rule, episodes

    def stopping_rule(self) -> SequentialRule | None:
        """A fresh sequential stopping rule for `target_halfwidth` (None for a fixed count):
        a rule fixes its design at its run's first look, so each run needs its own."""
        return self._counts()[0]

    @property
    def episodes(self) -> int:
        """How many seeds the run is given (a sequential run's cap)."""
        return self._counts()[1]

    def for_suite(self) -> RunSpec:
        """This spec, checked for a suite (every task runs it, one report over them): a
        setting a suite cannot honour is a `ConfigError` naming it, never silently dropped."""
        defaults = {f.name: f.default for f in dataclasses.fields(self)}
        for name, flag, why in SUITE_REFUSES:
            if getattr(self, name) != defaults[name]:
                raise ConfigError(
                    f"{name} ({flag}) does not apply to a suite: {why}; drop it (a suite honours "
                    "n_envs, n_episodes, seed, max_steps, batching and refill_every)"
                )
        return self


# What a suite cannot honour: (RunSpec field, CLI flag, why).
SUITE_REFUSES = (
    ("target_halfwidth", "--target-halfwidth", "every task runs the same fixed episode count"),
    ("factor_bins", "--factor-bins", "its report has no per-factor breakdown"),
    ("step_rewards", "--plots", "its report keeps no per-step rewards"),
)
