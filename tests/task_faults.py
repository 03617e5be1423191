"""A stand-in for a suite's per-task entry point in a task process (`suite._task_report`), for
the tests of task processes that die: it returns the report saved for the task, after killing
its own process with SIGKILL (as the system's out-of-memory killer does) where a marker file
says so: ``TASK.die`` every time, ``TASK.die-once`` the first time only. Reports and markers
are in the folder named by the environment variable `FOLDER` (task processes inherit it)."""

from __future__ import annotations

import os
import signal
from collections.abc import Mapping
from pathlib import Path
from typing import Any

from openral_mjx.report import EvalReport, load_report

FOLDER = "OPENRAL_MJX_TEST_TASK_FAULTS"


def run_task(scene: str, task: str, policy: str, options: Mapping[str, Any], spec) -> EvalReport:
    del scene, options, policy, spec
    folder = Path(os.environ[FOLDER])
    once = folder / f"{task}.die-once"
    if (folder / f"{task}.die").exists() or once.exists():
        once.unlink(missing_ok=True)
        os.kill(os.getpid(), signal.SIGKILL)
    return load_report(folder / f"{task}.json")
