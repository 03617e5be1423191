"""`eval --cluster`: a suite's tasks over a Ray cluster of two nodes on 127.0.0.1.

The `cluster` tests start the cluster once for the module (`ray start --head`, then a second
`ray start --address`, one CPU each, token authentication off as two nodes on one machine
need) and `ray stop` it at the end, also on failure. The suite is two tasks of the MetaWorld
mirror on `c` with MetaWorld's expert, a few seeds each: split over both nodes, and with one
worker killed mid-run, it gives per seed what a local run gives. So do a two-point sweep of
`tabletop_push` and a two-task suite of the MetaWorld host scene, one part per node. A host
scene's env workers run as actors on both nodes with a local run's episodes; one whose worker
process crashes fails only its own episodes, and one whose actor is killed is replaced and its
episodes replayed, ending as a local run's. Without Ray they are skipped
(`pip install 'openral_mjx[ray]'`), on CI (`CI` set) they fail. The checks of the flags that
need no cluster run in the default tier.
"""

from __future__ import annotations

import contextlib
import json
import os
import shutil
import signal
import socket
import subprocess
import sys
import threading
import time
from pathlib import Path

import pytest
from cli_runs import run_cli
from worker_envs import require_worker_envs

from openral_mjx.core.errors import ConfigError
from openral_mjx.evaluation import RunSpec, build_scene, cluster
from openral_mjx.evaluation import suite as suite_module
from openral_mjx.evaluation.partial import Interrupted
from openral_mjx.evaluation.sweep import SweepCluster, run_sweep
from openral_mjx.policies import make_policy
from openral_mjx.report import EvalReport, load_report
from openral_mjx.report.sweep import load_sweep
from openral_mjx.scenes.factor_ranges import parse_factors

TASKS = ["reach-v3", "pick-place-v3"]
RUN = {"n_envs": 2, "n_episodes": 2, "max_steps": 60}
ARGS = ("metaworld_mjx", "mt10", "metaworld-expert")
PART_TITLE = b"ray::_run_part"  # a Ray worker's process title while it runs a part
# Two nodes on one machine: no token authentication (else the second node is refused).
RAY_ENV = {"RAY_AUTH_MODE": "disabled"}


def require_ray() -> None:
    """Skip the calling test unless Ray is installed; on CI, which installs the `ray` extra
    (`.ci/run`), fail instead, so a broken install cannot turn these tests into skips."""
    try:
        cluster.require_ray()
    except ConfigError as e:
        if os.environ.get("CI"):
            raise RuntimeError(f"CI must install the ray extra: {e}") from None
        pytest.skip(str(e))


def outcomes(report: EvalReport) -> list[tuple]:
    """Each episode's task, seed, outcome, length and return: what a run decides per seed."""
    return [
        (e.metadata["task"], e.metadata["seed"], e.success, e.steps, e.total_reward)
        for e in report.episodes
    ]


def test_address_forms():
    for good in ("local", "auto", "10.0.0.1:6379", "head-node:6379", "ray://head:10001"):
        cluster.check_address(good)
    for bad in ("", "head", "head:port", "10.0.0.1:0", "10.0.0.1:70000", "http://h:1"):
        with pytest.raises(ConfigError, match="is not a Ray address; valid: local, auto"):
            cluster.check_address(bad)


def test_without_ray_is_one_config_error(monkeypatch):
    monkeypatch.setitem(sys.modules, "ray", None)  # `import ray` raises ImportError
    with pytest.raises(ConfigError, match=r"needs Ray.*pip install 'openral_mjx\[ray\]'"):
        cluster.require_ray()


def test_a_sweep_on_a_cluster_takes_its_policy_by_name():
    """The workers build the policy: a built one is refused before anything connects."""
    scene = build_scene("tabletop_push", backend="c", n_envs=2, threads=1)
    on_ray = SweepCluster("local", "tabletop_push", {})
    with pytest.raises(ConfigError, match="builds its policy on each worker: pass its name"):
        run_sweep(scene, make_policy("scripted", scene), SWEEP, RunSpec(), cluster=on_ray)


class _Lost(Exception):
    pass


class _FakeRay:
    """What `cluster.fan_out` uses of Ray: tasks run when `get` asks, `wait` returns the
    earliest submitted, as Ray starts queued tasks while resources free up."""

    exceptions = type(
        "exceptions",
        (),
        {
            "WorkerCrashedError": _Lost,
            "NodeDiedError": _Lost,
            "ObjectLostError": _Lost,
            "OutOfMemoryError": _Lost,
            "RayTaskError": RuntimeError,
        },
    )

    def __init__(self) -> None:
        self.submitted: list[tuple] = []

    def remote(self, **options):
        def wrap(run):
            def submit(fn, args):
                self.submitted.append(args)
                return (fn, args)

            return type("Remote", (), {"remote": staticmethod(submit)})

        return wrap

    def wait(self, refs, num_returns, timeout):
        return refs[:num_returns], refs[num_returns:]

    def get(self, ref):
        fn, args = ref
        return fn(*args), "node", "127.0.0.1"

    def cancel(self, ref, force):
        pass


def test_parts_go_to_the_cluster_in_the_order_asked():
    """A suite's tasks on a cluster are submitted longest first, as a pool of processes takes
    them: `fan_out` submits in `order` and yields each part under its own index."""
    ray = _FakeRay()
    parts = [(name, (name,)) for name in ("a", "bb", "ccc")]
    runs = list(cluster.fan_out(ray, len, parts, {}, order=[2, 0, 1]))
    assert ray.submitted == [("ccc",), ("a",), ("bb",)]
    assert [(i, n) for i, n, _ in runs] == [(2, 3), (0, 1), (1, 2)]
    assert [p.part for _, _, p in runs] == ["ccc", "a", "bb"]
    ray = _FakeRay()
    list(cluster.fan_out(ray, len, parts, {}))
    assert ray.submitted == [("a",), ("bb",), ("ccc",)]


@pytest.mark.cluster  # needs Ray, which the default tier does not install
def test_unreachable_cluster_is_refused_at_once():
    require_ray()
    with socket.socket() as s:  # a port nobody listens on
        s.bind(("127.0.0.1", 0))
        port = s.getsockname()[1]
    start = time.perf_counter()
    with (
        pytest.raises(ConfigError, match=f"cannot reach the Ray cluster at '127.0.0.1:{port}'"),
        cluster.connected(f"127.0.0.1:{port}"),
    ):
        pass
    assert time.perf_counter() - start < 2 * cluster.CONNECT_TIMEOUT_S


def _ray(*args: str) -> None:
    """Run the `ray` command line; a failure raises with what Ray printed."""
    ray_cli = Path(sys.executable).with_name("ray")
    command = [str(ray_cli) if ray_cli.exists() else shutil.which("ray") or "ray", *args]
    done = subprocess.run(
        command, env={**os.environ, **RAY_ENV}, capture_output=True, text=True, timeout=120
    )
    if done.returncode:
        said = (done.stderr.strip() or done.stdout.strip()).splitlines()[-3:]
        raise RuntimeError(f"`ray {' '.join(args)}` exited {done.returncode}: {' / '.join(said)}")


# Ports a Ray node takes by default for its other components (client server, dashboard, its
# agent, worker processes): a head port picked at random must not be one of them. CI's run once
# drew 52365, the dashboard agent's, and `ray start --head` refused it.
RAY_DEFAULT_PORTS = {6379, 8265, 10001, 52365, *range(10002, 20000)}


def free_head_port() -> int:
    """A port free on 127.0.0.1 that no other component of a default Ray node will take."""
    while True:
        with socket.socket() as s:
            s.bind(("127.0.0.1", 0))
            port = s.getsockname()[1]
        if port not in RAY_DEFAULT_PORTS:
            return port


@pytest.fixture(scope="module")
def two_nodes():
    """The address of a two-node Ray cluster on 127.0.0.1 (one CPU per node), this checkout's
    package on the workers' path, stopped after the module's tests."""
    require_ray()
    require_worker_envs("metaworld", module=False)  # the mirror's model files
    port = free_head_port()
    node = ["--node-ip-address", "127.0.0.1", "--num-cpus", "1", "--disable-usage-stats"]
    with pytest.MonkeyPatch.context() as mp:
        for key, value in RAY_ENV.items():
            mp.setenv(key, value)
        try:
            _ray("start", "--head", "--port", str(port), "--include-dashboard=false", *node)
            _ray("start", "--address", f"127.0.0.1:{port}", *node)
            yield f"127.0.0.1:{port}"
        finally:
            _ray("stop", "--force")


@pytest.fixture(scope="module")
def local_run() -> EvalReport:
    """The two tasks run here, one after the other: the per-seed reference."""
    with pytest.MonkeyPatch.context() as mp:
        mp.setattr(suite_module, "scene_suite", lambda scene, suite: TASKS)
        return suite_module.evaluate_suite(*ARGS, RunSpec(backend="c", threads=1, **RUN))


@pytest.mark.cluster
def test_suite_over_two_nodes_equals_a_local_run(
    two_nodes, local_run, monkeypatch, capsys, tmp_path
):
    """`eval --cluster` puts one task on each node and writes the report a local run writes,
    per seed, with where each task ran."""
    monkeypatch.setattr(suite_module, "scene_suite", lambda scene, suite: TASKS)
    out = tmp_path / "suite.json"
    code, stdout, err = run_cli(
        monkeypatch,
        capsys,
        *("--scene", "metaworld_mjx", "--suite", "mt10", "--policy", "metaworld-expert"),
        *("--backend", "c", "--threads", "1", "--n-envs", "2", "--max-steps", "60"),
        *("--cluster", two_nodes, "--out", str(out)),
    )
    assert code == 0, err
    report = load_report(out)
    assert outcomes(report) == outcomes(local_run)
    assert report.per_task == local_run.per_task
    assert report.cluster is not None and report.cluster.address == two_nodes
    assert report.cluster.nodes == 2 and report.cluster.retries == 0
    assert [p.part for p in report.cluster.parts] == TASKS
    assert [p.attempts for p in report.cluster.parts] == [1, 1]
    assert len({p.node_id for p in report.cluster.parts}) == 2  # one task per node
    assert "cluster 127.0.0.1" in stdout and "2 parts on 2 of 2 nodes" in stdout
    assert f"--cluster {two_nodes}" in json.loads(out.read_text())["command"]


SWEEP = "delay=0:12:2"  # the push expert succeeds without delay and fails with 12 steps of it


@pytest.mark.cluster
def test_sweep_over_two_nodes_equals_a_local_run(two_nodes, monkeypatch, capsys, tmp_path):
    """`eval --sweep --cluster` runs one point on each node and writes the sweep report a local
    sweep writes: per point, each seed's outcome, with where each point ran."""
    spec = RunSpec(backend="c", threads=1, n_envs=2, n_episodes=4, seed=0, max_steps=120)
    scene = build_scene("tabletop_push", backend="c", n_envs=2, threads=1)
    local = run_sweep(scene, "scripted", SWEEP, spec, randomize=parse_factors(["friction=0.5:1"]))
    out = tmp_path / "sweep.json"
    code, stdout, err = run_cli(
        monkeypatch,
        capsys,
        *("--scene", "tabletop_push", "--policy", "scripted", "--backend", "c"),
        *("--threads", "1", "--n-envs", "2", "--n-episodes", "4", "--max-steps", "120"),
        *("--sweep", SWEEP, "--randomize", "friction=0.5:1", "--cluster", two_nodes),
        *("--out", str(out)),
    )
    assert code == 0, err
    report = load_sweep(out)
    assert [(p.value, p.outcomes) for p in report.points] == [
        (p.value, p.outcomes) for p in local.points
    ]
    assert [p.outcomes for p in local.points] == ["1111", "0000"]  # the sweep sees a change
    assert report.steps == local.steps
    assert report.cluster is not None and report.cluster.address == two_nodes
    assert [p.part for p in report.cluster.parts] == ["0", "12"]
    assert report.cluster.retries == 0
    assert len({p.node_id for p in report.cluster.parts}) == 2  # one point per node
    assert "2 parts on 2 of 2 nodes" in stdout


def _titled(title: bytes) -> set[int]:
    """The pids of processes whose title starts with `title` (Ray titles a worker after the
    function or actor method it runs)."""
    pids = set()
    for proc in Path("/proc").iterdir():
        with contextlib.suppress(OSError):
            if proc.name.isdigit() and (proc / "cmdline").read_bytes().startswith(title):
                pids.add(int(proc.name))
    return pids


def _running_parts() -> set[int]:
    """The pids of Ray workers running a part now."""
    return _titled(PART_TITLE)


def _kill_busy(title: bytes, killed: list[int], stop: threading.Event, after_s: float) -> None:
    """SIGKILL the first process seen titled `title` for `after_s` on end: a Ray worker
    running a part, or an env worker's actor serving one request (the one whose env hangs:
    the others answer in milliseconds)."""
    since: dict[int, float] = {}
    while not stop.is_set() and not killed:
        now = time.monotonic()
        since = {pid: since.get(pid, now) for pid in _titled(title)}
        for pid, start in since.items():
            if now - start >= after_s:
                with contextlib.suppress(ProcessLookupError):
                    os.kill(pid, signal.SIGKILL)
                    killed.append(pid)
                break
        time.sleep(0.05)


@pytest.mark.cluster
def test_killed_worker_runs_its_task_again(two_nodes, local_run, monkeypatch):
    """A worker killed mid-task: the task runs again, the other's result is kept, the
    report counts one retry and per seed equals a local run."""
    monkeypatch.setattr(suite_module, "scene_suite", lambda scene, suite: TASKS)
    killed: list[int] = []
    stop = threading.Event()
    killer = threading.Thread(target=_kill_busy, args=(PART_TITLE, killed, stop, 2.0), daemon=True)
    killer.start()
    try:
        report = suite_module.evaluate_suite(
            *ARGS, RunSpec(backend="c", threads=1, **RUN), cluster=two_nodes
        )
    finally:
        stop.set()
        killer.join(timeout=10)
    assert len(killed) == 1
    assert outcomes(report) == outcomes(local_run)
    assert report.cluster is not None and report.cluster.retries == 1
    assert sorted(p.attempts for p in report.cluster.parts) == [1, 2]


@pytest.mark.cluster
def test_interrupt_cancels_the_running_tasks(two_nodes, local_run, monkeypatch):
    """Ctrl-C as the first task ends: the other task's worker is ended, not waited for, and
    what finished in the suite's order is kept as a partial report."""
    monkeypatch.setattr(suite_module, "scene_suite", lambda scene, suite: TASKS)

    def interrupt(done: int, total: int, task: str) -> None:
        raise KeyboardInterrupt

    with pytest.raises(KeyboardInterrupt) as stop:
        suite_module.evaluate_suite(
            *ARGS, RunSpec(backend="c", threads=1, **RUN), cluster=two_nodes, on_task=interrupt
        )
    deadline = time.monotonic() + 10
    while _running_parts() and time.monotonic() < deadline:
        time.sleep(0.1)
    assert _running_parts() == set()
    if isinstance(stop.value, Interrupted):  # the suite's first task was the one that ended
        kept = stop.value.report
        assert kept.partial is not None and kept.partial.finished == TASKS[:1]
        assert outcomes(kept) == outcomes(local_run)[: RUN["n_episodes"]]
        assert kept.cluster is not None and [p.part for p in kept.cluster.parts] == TASKS[:1]


HOST_RUN = ("--scene", "metaworld", "--task", "reach-v3", "--policy", "metaworld-expert")
HOST_RUN += ("--n-envs", "2", "--n-episodes", "4", "--max-steps", "40", "--batching", "chunks")


@pytest.mark.cluster
def test_host_scene_workers_as_actors_equal_local_workers(two_nodes, monkeypatch, capsys, tmp_path):
    """`eval --cluster` for a host scene (no --suite): its two env workers are Ray actors, one
    per node, each in its node's MetaWorld worker environment; per seed the episodes equal
    those of two local worker processes."""
    reports = {}
    for name, extra in (("local", ("--opt", "n_workers=2")), ("ray", ("--cluster", two_nodes))):
        out = tmp_path / f"{name}.json"
        code, _stdout, err = run_cli(monkeypatch, capsys, *HOST_RUN, *extra, "--out", str(out))
        assert code == 0, err
        reports[name] = load_report(out)
    local, ray = reports["local"], reports["ray"]
    assert len(outcomes(ray)) == 4 and outcomes(ray) == outcomes(local)
    assert all(e.metadata.get("error") is None for e in ray.episodes)
    backend = ray.options["backend"]
    assert backend["workers"] == 2 and len(backend["ray_nodes"]) == 2, backend  # both nodes
    assert "ray_nodes" not in local.options["backend"]
    assert "worker processes on Ray" in ray.device


@pytest.mark.cluster
def test_host_scene_suite_over_two_nodes_equals_a_local_run(
    two_nodes, monkeypatch, capsys, tmp_path
):
    """`eval --suite --cluster` for a host scene: each task runs on its own node, its env worker
    a process there in the node's MetaWorld worker environment; per seed the report is that of
    the same tasks run here one after the other."""
    monkeypatch.setattr(suite_module, "scene_suite", lambda scene, suite: TASKS)
    options = {"n_workers": 1}
    spec = RunSpec(n_envs=2, n_episodes=2, max_steps=40)
    local = suite_module.evaluate_suite(
        "metaworld", "mt10", "metaworld-expert", spec, options=options
    )
    out = tmp_path / "host_suite.json"
    code, stdout, err = run_cli(
        monkeypatch,
        capsys,
        *("--scene", "metaworld", "--suite", "mt10", "--policy", "metaworld-expert"),
        *("--n-envs", "2", "--n-episodes", "2", "--max-steps", "40", "--opt", "n_workers=1"),
        *("--cluster", two_nodes, "--out", str(out)),
    )
    assert code == 0, err
    report = load_report(out)
    assert len(outcomes(report)) == 4 and outcomes(report) == outcomes(local)
    assert all(e.metadata.get("error") is None for e in report.episodes)
    assert report.per_task == local.per_task
    assert report.cluster is not None and [p.part for p in report.cluster.parts] == TASKS
    assert len({p.node_id for p in report.cluster.parts}) == 2  # one task per node
    assert "2 parts on 2 of 2 nodes" in stdout


ACTOR_CALL = b"ray::_WorkerActor.call"  # an env worker's actor's title while it serves a request
POINT_RUN = ("--scene", "point_reach", "--policy", "random", "--n-envs", "4", "--n-episodes", "8")
POINT_RUN += ("--max-steps", "6", "--batching", "chunks")


@pytest.mark.cluster
def test_a_crashed_actor_worker_fails_only_its_own_episodes(
    two_nodes, monkeypatch, capsys, tmp_path
):
    """Fault isolation per episode is a local run's: on `point_reach`, seed 1's env crashes its
    worker process at its third step. Worker 0's envs (seeds 0 and 1) fail with that error (an
    env's own fault is not retried), a new actor takes worker 0's envs for the next chunk, and
    every other seed equals a clean run."""
    reports = {}
    faulty = ("--opt", "fault=crash", "fault_init_state=1", "fault_step=2")
    for name, extra in (("clean", ()), ("faulty", faulty)):
        out = tmp_path / f"{name}.json"
        code, _stdout, err = run_cli(
            monkeypatch, capsys, *POINT_RUN, "--cluster", two_nodes, *extra, "--out", str(out)
        )
        assert code == 0, err
        reports[name] = load_report(out)
    assert "on Ray" in reports["faulty"].device and "on Ray" in reports["clean"].device
    failed = [e.metadata["seed"] for e in reports["faulty"].episodes if e.metadata["error"]]
    assert failed == [0, 1]
    for ep in reports["faulty"].episodes[:2]:
        assert not ep.success and "worker 0 exited (exit code 3)" in ep.metadata["error"]
    rest = [o for o in outcomes(reports["faulty"]) if o[1] not in (0, 1)]
    assert rest == [o for o in outcomes(reports["clean"]) if o[1] not in (0, 1)]
    assert reports["faulty"].options["backend"]["ray_retries"] == 0


@pytest.mark.cluster
def test_a_killed_actor_s_episodes_run_again_on_a_new_one(two_nodes, monkeypatch, capsys, tmp_path):
    """An actor lost mid-chunk (its process killed, as when its node is lost) is not its
    episodes' fault: on `point_reach`, seed 1's env stalls at its third step and its actor's
    process is killed there; a new actor replays worker 0's chunk so far and goes on. Every
    episode equals a run on local worker processes, none failed, and the report counts one
    retry."""
    stall = ("--opt", "fault=stall", "fault_init_state=1", "fault_step=2", "n_workers=2")
    local_out, ray_out = tmp_path / "local.json", tmp_path / "ray.json"
    code, _stdout, err = run_cli(monkeypatch, capsys, *POINT_RUN, *stall, "--out", str(local_out))
    assert code == 0, err
    killed: list[int] = []
    stop = threading.Event()
    killer = threading.Thread(target=_kill_busy, args=(ACTOR_CALL, killed, stop, 1.0), daemon=True)
    killer.start()
    try:
        code, _stdout, err = run_cli(
            monkeypatch, capsys, *POINT_RUN, *stall, "--cluster", two_nodes, "--out", str(ray_out)
        )
    finally:
        stop.set()
        killer.join(timeout=10)
    assert code == 0, err
    assert len(killed) == 1
    local, ray = load_report(local_out), load_report(ray_out)
    assert "on Ray" in ray.device
    assert all(e.metadata.get("error") is None for e in ray.episodes)
    assert len(outcomes(ray)) == 8 and outcomes(ray) == outcomes(local)
    assert ray.options["backend"]["ray_retries"] == 1
