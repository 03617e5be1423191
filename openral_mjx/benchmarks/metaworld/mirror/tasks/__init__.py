"""The mirror tasks by MetaWorld name (`TASKS`): every module of this package that defines a
`TASKS` tuple of `MirrorTask`s (one module per family of MetaWorld tasks)."""

from __future__ import annotations

import importlib
import pkgutil

from openral_mjx.benchmarks.metaworld.mirror.task import MirrorTask
from openral_mjx.core.errors import ConfigError


def _collect() -> dict[str, MirrorTask]:
    tasks: dict[str, MirrorTask] = {}
    for info in sorted(pkgutil.iter_modules(__path__), key=lambda m: m.name):
        module = importlib.import_module(f"{__name__}.{info.name}")
        for task in getattr(module, "TASKS", ()):
            if task.name in tasks:
                raise RuntimeError(f"MetaWorld mirror task {task.name!r} defined twice")
            tasks[task.name] = task
    return tasks


TASKS: dict[str, MirrorTask] = _collect()


def rewarded_tasks() -> list[str]:
    """The tasks whose reward is MetaWorld's (`MirrorTask.has_reward`); the others return 0."""
    return sorted(name for name, task in TASKS.items() if task.has_reward)


def check_reward(task: str) -> None:
    """Refuse `task` for training where the mirror does not compute MetaWorld's reward."""
    if not TASKS[task].has_reward:
        raise ConfigError(
            f"metaworld_mjx task {task!r} has no reward: the mirror computes MetaWorld's reward "
            f"only for {', '.join(rewarded_tasks())} (elsewhere it is 0, so PPO would learn "
            f"nothing); finetune one of those, or evaluate {task} with openral_mjx.eval"
        )
