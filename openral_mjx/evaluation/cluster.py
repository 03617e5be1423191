"""Ray as the fan-out engine: independent parts of a run (a suite's tasks) as Ray tasks.

`eval --suite S --cluster ADDRESS` sends each task of the suite to a Ray cluster, where it runs
the same per-task entry point a local `--task-processes` run gives its processes, so per seed
the episodes are a local run's. Ray schedules the parts (spread over the nodes, one GPU each
where the cluster has GPUs and the backend uses them, else a CPU share); this module adds
only what Ray leaves to its caller: running a part again when the worker or node under it
died (counted, and recorded with where each part ended in `ClusterInfo`), and cancelling
every part on Ctrl-C. The cluster runs the driver's own `openral_mjx` (shipped as a Ray
`py_modules` package) in each node's Python environment, which must hold the package's
dependencies (and any worker environment a scene reads, e.g. MetaWorld's for its mirror).

Ray is an optional extra (`pip install 'openral_mjx[ray]'`), imported only here and only when
a cluster is asked for.
"""

from __future__ import annotations

import contextlib
import dataclasses
import re
import socket
from collections.abc import Callable, Iterator, Sequence
from pathlib import Path
from types import ModuleType
from typing import Any, Protocol, TypeVar

from openral_mjx.core.errors import ConfigError
from openral_mjx.report import ClusterInfo, PartPlacement

R = TypeVar("R")

LOCAL = "local"  # a one-node cluster started in this process, ended with the run
AUTO = "auto"  # the cluster `ray start` runs on this machine (its address file)
# A part whose worker or node died runs again, up to this many starts in all.
MAX_ATTEMPTS = 4
CONNECT_TIMEOUT_S = 5.0
WAIT_S = 0.5  # how long one wait for finished parts blocks (Ctrl-C lands between waits)
_ADDRESS = re.compile(r"(?:ray://)?(?P<host>[\w.-]+|\[[0-9a-fA-F:]+\]):(?P<port>\d{1,5})")
PACKAGE = Path(__file__).resolve().parents[1]  # openral_mjx/, shipped to the workers


def require_ray() -> ModuleType:
    """The `ray` module, or a `ConfigError` saying how to install it."""
    try:
        import ray
    except ImportError:
        raise ConfigError(
            "--cluster needs Ray, which is not installed: pip install 'openral_mjx[ray]'"
        ) from None
    return ray


def check_address(address: str) -> None:
    """`address` is `local`, `auto`, HOST:PORT or ray://HOST:PORT (a `ConfigError` if not)."""
    if address in (LOCAL, AUTO):
        return
    match = _ADDRESS.fullmatch(address)
    if match is None or not 0 < int(match["port"]) < 65536:
        raise ConfigError(
            f"--cluster {address!r} is not a Ray address; valid: local, auto, HOST:PORT, "
            "ray://HOST:PORT"
        )


def _reachable(address: str) -> None:
    """Refuse a HOST:PORT nobody listens on at once (`ray.init` would retry for minutes)."""
    match = _ADDRESS.fullmatch(address)
    if match is None:
        return
    host = match["host"].strip("[]")
    try:
        with socket.create_connection((host, int(match["port"])), timeout=CONNECT_TIMEOUT_S):
            pass
    except OSError as e:
        raise ConfigError(f"cannot reach the Ray cluster at {address!r}: {e}") from None


@contextlib.contextmanager
def connected(address: str) -> Iterator[ModuleType]:
    """Ray connected to the cluster at `address` (see `check_address`) for the block, then
    disconnected (a `local` cluster is ended); a connection Ray already has is used as it is
    and left open. An unreachable cluster is a `ConfigError`."""
    ray = require_ray()
    check_address(address)
    if ray.is_initialized():
        yield ray
        return
    _reachable(address)
    # Prepended to each worker's path: the cluster runs the code the driver runs. Workers of
    # a GPU share it with others: allocate its memory as needed, not 75% of it up front.
    runtime_env = {
        "py_modules": [str(PACKAGE)],
        "env_vars": {"XLA_PYTHON_CLIENT_PREALLOCATE": "false"},
    }
    kwargs: dict[str, Any] = {"runtime_env": runtime_env, "log_to_driver": False}
    if address == LOCAL:
        kwargs["include_dashboard"] = False
    else:
        kwargs["address"] = address
    try:
        ray.init(**kwargs)
    except ConnectionError as e:
        raise ConfigError(f"cannot reach the Ray cluster at {address!r}: {e}") from None
    try:
        yield ray
    finally:
        ray.shutdown()


def part_resources(ray: ModuleType, backend: str, threads: int | None) -> dict[str, float]:
    """What one part asks the cluster for: a GPU (and a CPU) where the cluster has GPUs and
    `backend` runs on one, else `threads` CPUs (default 1); a `ConfigError` if no node has
    that many (Ray would wait for one forever)."""
    if backend in ("mjx", "warp") and ray.cluster_resources().get("GPU", 0) >= 1:
        return {"num_gpus": 1, "num_cpus": 1}
    cpus = threads or 1
    largest = max((n["Resources"].get("CPU", 0) for n in ray.nodes() if n["Alive"]), default=0)
    if cpus > largest:
        raise ConfigError(
            f"--threads {cpus}: no node of the Ray cluster has that many CPUs (largest: "
            f"{largest:g}); give at most {int(largest)}"
        )
    return {"num_cpus": cpus}


def _run_part(fn: Callable[..., R], args: tuple) -> tuple[R, str, str]:
    """On a Ray worker: `fn(*args)`, with the id and IP address of the node that ran it."""
    import ray

    return fn(*args), ray.get_runtime_context().get_node_id(), ray.util.get_node_ip_address()


def fan_out(
    ray: ModuleType,
    fn: Callable[..., R],
    parts: Sequence[tuple[str, tuple]],
    resources: dict[str, float],
    *,
    order: Sequence[int] | None = None,
    max_attempts: int = MAX_ATTEMPTS,
) -> Iterator[tuple[int, R, PartPlacement]]:
    """Run `fn(*args)` for each `(name, args)` of `parts` as a Ray task asking `resources`,
    spread over the nodes, submitted in `order` (part indices; default: as given), which Ray
    follows as resources free up; yield `(index, result, placement)` as each ends, in any
    order.

    A part whose worker or node died (`WorkerCrashedError`, `NodeDiedError`, a lost result,
    Ray's out-of-memory kill) is started again, at most `max_attempts` times in all; an error
    the part itself raised is raised here as itself. Leaving early (an error, Ctrl-C, the
    caller closing the generator) cancels every part still running."""
    lost = (
        ray.exceptions.WorkerCrashedError,
        ray.exceptions.NodeDiedError,
        ray.exceptions.ObjectLostError,
        ray.exceptions.OutOfMemoryError,
    )
    remote = ray.remote(max_retries=0, scheduling_strategy="SPREAD", **resources)(_run_part)
    attempts = [1] * len(parts)
    indices = range(len(parts)) if order is None else order
    pending = {remote.remote(fn, parts[i][1]): i for i in indices}
    try:
        while pending:
            done, _ = ray.wait(list(pending), num_returns=1, timeout=WAIT_S)
            for ref in done:
                i = pending.pop(ref)
                try:
                    result, node_id, node_ip = ray.get(ref)
                except lost:
                    if attempts[i] >= max_attempts:
                        raise
                    attempts[i] += 1
                    pending[remote.remote(fn, parts[i][1])] = i
                    continue
                except ray.exceptions.RayTaskError as e:
                    # the part's own error, as itself (a ConfigError stays one) where Ray
                    # could send it back
                    raise (e.cause if isinstance(e.cause, BaseException) else e) from e
                yield i, result, PartPlacement(parts[i][0], node_id, node_ip, attempts[i])
    finally:
        for ref in pending:
            ray.cancel(ref, force=True)


def live_nodes(ray: ModuleType) -> int:
    """How many nodes of the connected cluster are alive."""
    return sum(1 for n in ray.nodes() if n["Alive"])


def cluster_info(address: str, nodes: int, placements: Sequence[PartPlacement]) -> ClusterInfo:
    """The report's record of a run on the cluster at `address` (`nodes` alive when it
    started): the retries, and where each part ran (`placements` in the run's order)."""
    return ClusterInfo(
        address=address,
        nodes=nodes,
        retries=sum(p.attempts - 1 for p in placements),
        parts=list(placements),
    )


class _ClusterRecord(Protocol):
    """A report that may record an earlier run on a cluster (a suite's or a sweep's)."""

    cluster: ClusterInfo | None


@dataclasses.dataclass
class RayRun:
    """A run on a Ray cluster so far: the address, its live nodes, where each part in the
    report ran (a resumed cluster run's parts first, from the `earlier` report)."""

    address: str
    earlier: _ClusterRecord | None
    nodes: int = 0
    placements: list[PartPlacement] = dataclasses.field(default_factory=list)

    def info(self) -> ClusterInfo:
        before = self.earlier.cluster if self.earlier is not None else None
        parts = [*(before.parts if before is not None else []), *self.placements]
        return cluster_info(self.address, self.nodes, parts)
