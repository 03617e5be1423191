"""The mirror tasks by MetaWorld name (`TASKS`): every module of this package that defines a
`TASKS` tuple of `MirrorTask`s (one module per family of MetaWorld tasks)."""

from __future__ import annotations

import importlib
import pkgutil

from openral_mjx.scenes.metaworld_mjx.task import MirrorTask


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
