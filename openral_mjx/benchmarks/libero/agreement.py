"""The LIBERO mirror against LIBERO itself: LIBERO's env for a task in a worker process, to
replay actions from an initial state and to judge states by its own goal predicates."""

from __future__ import annotations

import contextlib
from collections.abc import Iterator
from typing import Any

import numpy as np

from openral_mjx.benchmarks.libero.assets import TIMEOUT_S, task_worker
from openral_mjx.host.pool import Worker


class LiberoReference:
    """LIBERO's env for one task, in a worker (`openral_mjx.benchmarks.libero.export`)."""

    def __init__(self, worker: Worker) -> None:
        self.worker = worker

    def _call(self, method: str, **kwargs: Any) -> Any:
        return self.worker.call({"op": "call", "method": method, "kwargs": kwargs}, TIMEOUT_S)

    def rollout(self, init: int, actions: np.ndarray) -> dict[str, np.ndarray]:
        """Initial state `init`, LIBERO's settle, then `actions`: per step 0..T the joint
        positions and velocities, lerobot's state and the goal."""
        return self._call("rollout", init=int(init), actions=np.asarray(actions, np.float64))

    def check_success(self, states: np.ndarray) -> np.ndarray:
        """LIBERO's goal at each flattened ``[time, qpos, qvel]`` state."""
        return np.asarray(self._call("check_success", states=np.asarray(states, np.float64)))


@contextlib.contextmanager
def libero_reference(task: str) -> Iterator[LiberoReference]:
    """LIBERO's env for `task` (``suite/index``) in a worker, closed on exit."""
    with task_worker(task) as (worker, _):
        yield LiberoReference(worker)
