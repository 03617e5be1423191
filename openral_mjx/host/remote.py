"""Env workers as Ray actors: a host scene's simulators on any node of a Ray cluster.

A `RayWorker` stands where a local `Worker` stands in `EnvBatch` (the same `send`, `receive`,
`call`, `close`, `kill`). It is a Ray actor, placed by Ray on any node with a free CPU, that
builds the worker environment by its recipe on first use on that node (`ensure_env`), starts
one ordinary `Worker` there and passes each request through. Requests and replies are the same
messages, so episodes, their per-slot seeds and the per-episode fault isolation are those of a
local run: a worker that fails (its process crashed, or it missed a deadline) fails only its own
slots. An actor lost under a running worker (its process killed, its node gone) is not the
episodes' fault: `ActorLost` tells `EnvBatch` to replay them on a new actor.
"""

from __future__ import annotations

import contextlib
import tempfile
from pathlib import Path
from types import ModuleType
from typing import Any

from openral_mjx.host.envs import ensure_env
from openral_mjx.host.pool import RemoteError, Worker, WorkerFailure

# Beyond a request's own deadline (which the actor's `Worker` enforces), what Ray may take to
# carry it there and back before the actor counts as lost.
TRANSPORT_S = 60.0
# What an actor may take to start on a node that first builds the worker environment there
# (LIBERO's: ~2 min with uv and a warm cache, more from an empty one).
BUILD_S = 3600.0


class ActorLost(WorkerFailure):
    """The worker's Ray actor died under it (its process or node was lost), not its env."""


def _first(error: Exception) -> str:
    """The first line of a Ray error (its tracebacks run to pages)."""
    text = str(error).strip()
    return text.splitlines()[0] if text else type(error).__name__


class _WorkerActor:
    """The actor's side: one local `Worker` in the node's copy of the worker environment.
    Failures come back as values (Ray would wrap raised ones in its own error type)."""

    def __init__(self, env_name: str, env: dict[str, str], name: str) -> None:
        python = ensure_env(env_name)  # built by the recipe on this node's first use
        logs = Path(tempfile.mkdtemp(prefix="openral_mjx_ray_worker_"))
        self._worker = Worker(python, env, logs / "worker.log", name=name)

    def call(self, msg: dict[str, Any], timeout: float | None) -> tuple[str, Any, str]:
        try:
            return "ok", self._worker.call(msg, timeout), ""
        except RemoteError as e:
            return "remote", str(e), e.remote_traceback
        except WorkerFailure as e:
            return "failure", str(e), ""

    def where(self) -> str:
        import ray

        node = ray.get_runtime_context().get_node_id()
        return f"{ray.util.get_node_ip_address()} ({node[:8]})"

    def close(self) -> None:
        self._worker.close()


class RayWorker:
    """A worker hosted by a Ray actor on whichever node Ray picks (see module doc).

    Args:
        ray: the connected `ray` module.
        env_name: the worker environment to build or find on that node (`envs.RECIPES`).
        env: extra environment variables for the worker process.
        name: for messages.
        deadlines: seconds the actor's worker has for a `step` request, and for any other
            (`EnvBatch` gives the same to `receive`).
    """

    def __init__(
        self,
        ray: ModuleType,
        env_name: str,
        env: dict[str, str],
        name: str,
        deadlines: tuple[float, float],
    ) -> None:
        self.name = name
        self._ray = ray
        self._deadlines = deadlines
        actor = ray.remote(num_cpus=1, max_restarts=0, max_concurrency=1)(_WorkerActor)
        self._actor = actor.options(scheduling_strategy="SPREAD").remote(env_name, env, name)
        self._pending: Any = None
        self._alive = True

    @property
    def alive(self) -> bool:
        return self._alive

    def send(self, msg: dict[str, Any]) -> None:
        """Queue a request; `receive` collects the reply."""
        if not self._alive:
            raise WorkerFailure(f"{self.name} exited")
        step, other = self._deadlines
        self._pending = self._actor.call.remote(msg, step if msg.get("method") == "step" else other)

    def receive(self, timeout: float | None) -> Any:
        """The reply to the last request; `WorkerFailure` if the worker failed or missed the
        deadline (the actor is killed then), `ActorLost` (one) if its actor or node was lost,
        `RemoteError` if it raised."""
        ray = self._ray
        ref = self._pending
        wait = None if timeout is None else timeout + TRANSPORT_S
        try:
            status, value, trace = ray.get(ref, timeout=wait)
        except ray.exceptions.GetTimeoutError:
            self.kill()
            raise WorkerFailure(f"{self.name} did not answer within {timeout:g} s") from None
        except ray.exceptions.RayError as e:
            self.kill()
            raise ActorLost(f"{self.name} lost its Ray actor: {_first(e)}") from None
        self._pending = None  # answered (on Ctrl-C in `ray.get` it stays set: see `close`)
        if status == "remote":
            raise RemoteError(value, trace)
        if status == "failure":
            self.kill()
            raise WorkerFailure(value)
        return value

    def call(self, msg: dict[str, Any], timeout: float | None) -> Any:
        self.send(msg)
        return self.receive(timeout)

    def where(self) -> str:
        """The node the actor runs on, once it has started there: its IP address and the start
        of its Ray node ID (nodes of one machine share the address). Its start may build the
        worker environment on that node (minutes, see `envs`): `WorkerFailure` if that fails or
        takes over `BUILD_S`."""
        ray = self._ray
        try:
            return str(ray.get(self._actor.where.remote(), timeout=BUILD_S))
        except ray.exceptions.GetTimeoutError:
            self.kill()
            raise WorkerFailure(f"{self.name}: its actor did not start in {BUILD_S:g} s") from None
        except ray.exceptions.RayError as e:
            self.kill()
            raise WorkerFailure(f"{self.name}: its actor could not start: {_first(e)}") from None

    def close(self, timeout: float = 5.0) -> None:
        """Ask the worker to finish, then end the actor; one still serving a request (a run
        stopped mid-step) is ended at once, not waited for."""
        if self._alive and self._pending is None:
            with contextlib.suppress(Exception):  # closing: the actor goes either way
                self._ray.get(self._actor.close.remote(), timeout=timeout)
        self.kill()

    def kill(self) -> None:
        if self._alive:
            self._alive = False
            with contextlib.suppress(Exception):  # already gone with its node
                self._ray.kill(self._actor)
