"""A batch of N gym-style envs spread over worker processes, stepped all at once.

Env slot i (the i-th env of the runner's batch) lives in one worker; workers hold contiguous
blocks of slots and step theirs in turn, all workers in parallel. A batch call sends every
worker its request first, then collects the replies, each with a deadline. Faults stay local:
an env that raises fails its own slot; a worker that crashes or misses its deadline is killed
and fails the slots it held; the others finish. On Ray, a worker whose actor was lost (its
process killed, its node gone: not its envs' doing) is started again on a new actor, which
replays the chunk's requests to that worker (its reset and every step so far), so its episodes
go on as they were, seed for seed; `retries` counts these restarts. Failed and finished slots
are not stepped again: they return their last observation. Errors are numbered (1, 2, ...) so
that the jitted loop can carry them as integers; `messages[code - 1]` is the text.
"""

from __future__ import annotations

import contextlib
import dataclasses
import os
import shutil
import tempfile
from pathlib import Path
from types import ModuleType
from typing import Any

import numpy as np

from openral_mjx.core.errors import ConfigError
from openral_mjx.host.pool import RemoteError, Worker, WorkerFailure
from openral_mjx.host.remote import ActorLost, RayWorker

# Restarts of one worker's lost actor within one chunk before its slots fail (a node that
# keeps losing actors is not waited on forever).
MAX_ACTOR_RETRIES = 2


@dataclasses.dataclass(frozen=True)
class BatchConfig:
    """What to run in the workers and how.

    Attributes:
        python: interpreter of the workers' environment.
        factory: ``module:callable`` returning one gym-style env (see `gym_batch`).
        kwargs: the factory's keyword arguments (JSON types).
        observation: name -> (shape, dtype string) of every observation array.
        action_size: length of an action.
        n_workers: worker processes (at most one per env); None: one per core.
        step_timeout_s: deadline of one batched step.
        reset_timeout_s: deadline of one batched reset (the first builds the envs).
        env: extra environment variables for the workers.
        factors: names of the episode factors each env reports at reset (`gym_batch`); every
            result then holds them as ``factors`` (n, len(factors)) float32.
        path_first: directories put first on the workers' import path (e.g.
            `envs.our_mujoco_path`); local workers only.
    """

    python: str
    factory: str
    kwargs: dict[str, Any]
    observation: dict[str, tuple[tuple[int, ...], str]]
    action_size: int
    n_workers: int | None = None
    step_timeout_s: float = 60.0
    reset_timeout_s: float = 600.0
    env: dict[str, str] = dataclasses.field(default_factory=dict)
    factors: tuple[str, ...] = ()
    path_first: tuple[str, ...] = ()


def default_workers() -> int:
    try:
        return len(os.sched_getaffinity(0))
    except AttributeError:  # pragma: no cover - non-Linux
        return os.cpu_count() or 1


class EnvBatch:
    """N envs in worker processes; `reset` and `step` take and return whole-batch arrays."""

    def __init__(self, config: BatchConfig) -> None:
        self.config = config
        self.messages: list[str] = []
        self._workers: list[Worker | RayWorker | None] = []
        # on Ray: (ray, the worker environment, the cluster's CPUs when it was given)
        self._ray: tuple[ModuleType, str, int] | None = None
        self.nodes: list[str] = []  # per worker on Ray: its node, "IP (node ID start)"
        self._blocks: list[list[int]] = []
        self._n = 0
        self._logs = Path(tempfile.mkdtemp(prefix="openral_mjx_workers_"))
        self._last: dict[str, Any] = {}
        self._ended = np.zeros(0, bool)
        self.busy_s: list[float] = []  # per worker: seconds spent in env code since the reset
        self.busy_total_s: list[float] = []  # the same over every call since the layout was set
        # On Ray, per worker: the requests sent since the chunk's reset (replayed on a new
        # actor when its actor is lost) and that chunk's restarts; `retries`: all restarts.
        self._sent: list[list[dict[str, Any]]] = []
        self._restarts: list[int] = []
        self.retries = 0

    @property
    def n(self) -> int:
        return self._n

    @property
    def log_dir(self) -> Path:
        return self._logs

    def _error(self, message: str) -> int:
        self.messages.append(message)
        return len(self.messages)

    def on_ray(self, ray: ModuleType, env_name: str) -> None:
        """Start the workers as Ray actors on the connected cluster's nodes from now on, each
        in that node's copy of worker environment `env_name` (see `openral_mjx.host.remote`);
        by default as many as the cluster has CPUs."""
        if self.config.path_first:
            first = ", ".join(self.config.path_first)
            raise ConfigError(
                f"workers with packages put first on their path ({first}) run on this machine "
                "only, not on a Ray cluster"
            )
        self._stop()
        self._n = 0  # the next reset lays the slots out again, over the cluster's workers
        self._ray = (ray, env_name, int(ray.cluster_resources().get("CPU", 1)))

    def workers_for(self, n: int) -> int:
        """Worker processes for `n` envs: --opt n_workers, else one per core of this machine
        (of the cluster on Ray), at most one per env."""
        if self.config.n_workers:
            cores = self.config.n_workers
        elif self._ray is not None:
            cores = self._ray[2]
        else:
            cores = default_workers()
        return max(1, min(n, cores))

    def _start(self, w: int) -> Worker | RayWorker:
        c = self.config
        worker: Worker | RayWorker
        if self._ray is None:
            log = self._logs / f"worker{w}.log"
            worker = Worker(c.python, c.env, log, name=f"worker {w}", path_first=c.path_first)
        else:
            ray, env_name, _ = self._ray
            deadlines = (c.step_timeout_s, c.reset_timeout_s)
            worker = RayWorker(ray, env_name, c.env, f"worker {w}", deadlines)
            self.nodes[w] = worker.where()
        init = {
            "op": "init",
            "factory": "openral_mjx.host.gym_batch:GymBatch",
            "kwargs": {
                "factory": c.factory,
                "kwargs": c.kwargs,
                "n": len(self._blocks[w]),
                "observation": {k: [list(s), d] for k, (s, d) in c.observation.items()},
                **({"factors": list(c.factors)} if c.factors else {}),
            },
        }
        worker.call(init, c.reset_timeout_s)
        return worker

    def resize(self, n: int) -> None:
        """Lay out `n` slots over the workers (restarting them if the layout changes)."""
        if n == self._n and self._workers:
            return
        self._stop()
        n_workers = self.workers_for(n)
        bounds = np.linspace(0, n, n_workers + 1).round().astype(int)
        self._blocks = [list(range(bounds[w], bounds[w + 1])) for w in range(n_workers)]
        self._workers = [None] * n_workers
        self.nodes = [""] * n_workers if self._ray is not None else []
        self.busy_s = [0.0] * n_workers
        self.busy_total_s = [0.0] * n_workers
        self._sent = [[] for _ in range(n_workers)]
        self._restarts = [0] * n_workers
        self._n = n
        self._ended = np.ones(n, bool)
        self._last = {
            "obs": {
                k: np.zeros((n, *s), np.dtype(d)) for k, (s, d) in self.config.observation.items()
            },
            "reward": np.zeros(n, np.float32),
            "terminated": np.ones(n, bool),
            "success": np.zeros(n, bool),
            "diverged": np.zeros(n, bool),
            "error": np.zeros(n, np.int32),
        }
        if self.config.factors:
            self._last["factors"] = np.zeros((n, len(self.config.factors)), np.float32)

    def start(self, n: int) -> None:
        """Lay out `n` slots and start every worker with its envs built (a failure here is
        raised: nothing has run yet)."""
        self.resize(n)
        for w, worker in enumerate(self._workers):
            if worker is None:
                worker = self._workers[w] = self._start(w)
            worker.call({"op": "call", "method": "build"}, self.config.reset_timeout_s)

    def _fail_block(self, w: int, message: str) -> None:
        code = self._error(message)
        for i in self._blocks[w]:
            self._last["error"][i] = code
            self._last["terminated"][i] = True
            self._ended[i] = True
        worker = self._workers[w]
        if worker is not None:
            worker.kill()
        self._workers[w] = None

    def _exchange(self, requests: dict[int, dict[str, Any]], timeout: float) -> dict[int, Any]:
        """Send each worker its request, then collect every reply (failures are recorded)."""
        sent = []
        for w, msg in requests.items():
            worker = self._workers[w]
            try:
                if worker is None or not worker.alive:
                    worker = self._workers[w] = self._start(w)
                worker.send(msg)
                sent.append(w)
            except (WorkerFailure, RemoteError) as e:
                self._fail_block(w, str(e))
        replies = {}
        for w in sent:
            worker = self._workers[w]
            assert worker is not None
            try:
                try:
                    replies[w] = worker.receive(timeout)
                except ActorLost:
                    if self._restarts[w] >= MAX_ACTOR_RETRIES:
                        raise
                    replies[w] = self._replay(w, requests[w], timeout)
            except (WorkerFailure, RemoteError) as e:
                self._fail_block(w, str(e))
        if self._ray is not None:
            for w in requests:
                self._sent[w].append(requests[w])
        return replies

    def _replay(self, w: int, msg: dict[str, Any], timeout: float) -> Any:
        """Worker `w`'s reply to `msg` from a new actor, after this chunk's earlier requests to
        it are replayed there (their replies dropped): envs are deterministic per seed and
        actions, so it stands where the lost one stood. Raises as `receive` does."""
        self._restarts[w] += 1
        self.retries += 1
        self._workers[w] = None
        worker = self._workers[w] = self._start(w)
        for earlier in self._sent[w]:
            is_step = earlier.get("method") == "step"
            worker.call(earlier, self.config.step_timeout_s if is_step else timeout)
        return worker.call(msg, timeout)

    def _store(self, w: int, slots: list[int], reply: dict[str, Any]) -> None:
        self.busy_s[w] += reply["busy_s"]
        self.busy_total_s[w] += reply["busy_s"]
        last = self._last
        for j, i in enumerate(slots):
            for k in last["obs"]:
                last["obs"][k][i] = reply["obs"][k][j]
            last["reward"][i] = reply["reward"][j]
            last["success"][i] = reply["success"][j]
            last["diverged"][i] = bool(reply["diverged"][j]) if "diverged" in reply else False
            last["terminated"][i] = reply["terminated"][j]
            err = reply["errors"][j]
            last["error"][i] = 0 if err is None else self._error(f"env {i}: {err}")
            self._ended[i] = bool(reply["terminated"][j])
            if "factors" in reply and "factors" in last:
                last["factors"][i] = reply["factors"][j]

    def _result(self, rewards: np.ndarray) -> dict[str, Any]:
        last = self._last
        out = {
            "obs": {k: v.copy() for k, v in last["obs"].items()},
            "reward": rewards,
            "terminated": last["terminated"].copy(),
            "success": last["success"].copy(),
            "diverged": last["diverged"].copy(),
            "error": last["error"].copy(),
        }
        if "factors" in last:
            out["factors"] = last["factors"].copy()
        return out

    def reset(self, seeds: np.ndarray, options: list[dict[str, Any]]) -> dict[str, Any]:
        """Reset all `len(seeds)` slots (a new chunk of episodes): slot i gets seeds[i]."""
        self.resize(len(seeds))
        self.busy_s = [0.0] * len(self._blocks)
        self._last["error"][:] = 0
        self._last["success"][:] = False
        self._last["diverged"][:] = False
        if "factors" in self._last:
            self._last["factors"][:] = 0.0
        self._sent = [[] for _ in self._blocks]  # a new chunk: nothing to replay before it
        self._restarts = [0] * len(self._blocks)
        requests = {
            w: {
                "op": "call",
                "method": "reset",
                "kwargs": {
                    "slots": list(range(len(block))),
                    "seeds": [int(seeds[i]) for i in block],
                    "options": [options[i] for i in block],
                },
            }
            for w, block in enumerate(self._blocks)
        }
        for w, reply in self._exchange(requests, self.config.reset_timeout_s).items():
            self._store(w, self._blocks[w], reply)
        return self._result(np.zeros(self._n, np.float32))

    def step(self, actions: np.ndarray, done: np.ndarray) -> dict[str, Any]:
        """Step every slot that is neither `done` (per the caller) nor ended (per its env)."""
        active = ~(self._ended | np.asarray(done, bool))
        self._ended |= np.asarray(done, bool)
        requests, stepped = {}, {}
        for w, block in enumerate(self._blocks):
            local = [j for j, i in enumerate(block) if active[i]]
            if local:
                rows = np.stack([actions[block[j]] for j in local]).astype(np.float32)
                requests[w] = {
                    "op": "call",
                    "method": "step",
                    "kwargs": {"slots": local, "actions": rows},
                }
                stepped[w] = [block[j] for j in local]
        rewards = np.zeros(self._n, np.float32)
        for w, reply in self._exchange(requests, self.config.step_timeout_s).items():
            self._store(w, stepped[w], reply)
            rewards[stepped[w]] = reply["reward"]
        return self._result(rewards)

    def _stop(self) -> None:
        for worker in self._workers:
            if worker is not None:
                with contextlib.suppress(Exception):
                    worker.close()
        self._workers = [None] * len(self._workers)

    def close(self) -> None:
        """Stop the workers; their logs are kept only if something failed."""
        self._stop()
        if not self.messages:
            shutil.rmtree(self._logs, ignore_errors=True)
