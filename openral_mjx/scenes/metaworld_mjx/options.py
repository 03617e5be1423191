"""`metaworld_mjx` options."""

from __future__ import annotations

import dataclasses

from openral_mjx.core.errors import unknown
from openral_mjx.core.options import check

MAX_PATH_LENGTH = 500


@dataclasses.dataclass(frozen=True)
class MetaWorldMjxOptions:
    """The MetaWorld task (a name of `TASKS`), whether the goal is observed (MT benchmarks:
    true; ML: false, as MetaWorld's goal-hidden envs), and the episode limit (MetaWorld's 500)."""

    task: str = "reach-v3"
    goal_observable: bool = True
    max_steps: int = MAX_PATH_LENGTH

    def __post_init__(self) -> None:
        from openral_mjx.scenes.metaworld_mjx.tasks import TASKS

        if self.task not in TASKS:
            raise unknown("MetaWorld mirror task", self.task, sorted(TASKS))
        check(
            1 <= self.max_steps <= MAX_PATH_LENGTH,
            f"option max_steps={self.max_steps}: must be in 1..{MAX_PATH_LENGTH} "
            "(MetaWorld's limit)",
        )
