"""Ray against the local fan-out on one machine (issue 39's Measure item), in one call.

1. `suite`: a suite's tasks (default the MetaWorld mirror's `mt10`) one after another, with
   `--task-processes K`, and over Ray (`--cluster`) with K workers: a one-node Ray cluster
   started here with K GPUs (or, with no GPU, K CPUs: one part each), for K in `--workers`
   (default 1, 2, 4, ... up to the machine's GPUs, or its cores without GPUs). On one GPU,
   task processes share it (start NVIDIA's MPS daemon for them to overlap).
2. `host`: a host scene's eval (default LIBERO's `libero_spatial/0`, random actions) with its
   env workers as K local processes, then as K Ray actors (a one-node cluster of K CPUs), for
   K in `--host-workers` (default 1, 2, 4, ... up to the machine's cores).

Every run is timed by the wall clock around it (scene build, compile and run, as a user waits
for it) and keeps the report's run and compile times. Each row says whether its per-seed
outcomes equal the first run of its part (they must: a mismatch is a bug). One JSON row per run
goes to stdout and to `--out` (appended); a table follows.

    python benchmarks/cluster_scaling.py --out cluster_scaling.jsonl
    python benchmarks/cluster_scaling.py --parts suite --suite mt50 --backend warp \
        --n-envs 1000 --n-episodes 1000 --workers 1 2
    python benchmarks/cluster_scaling.py --parts host --host-n 64 --host-steps 220 \
        --host-workers 1 2 4 8 16
    JAX_PLATFORMS=cpu python benchmarks/cluster_scaling.py --backend c --first-tasks 2 \
        --n-envs 2 --n-episodes 2 --max-steps 20 --workers 1 2 --host-scene metaworld \
        --host-task reach-v3 --host-n 2 --host-steps 10 --host-workers 1 2   # a check on CPU
"""

from __future__ import annotations

import argparse
import json
import os
import platform
import sys
import time
from collections.abc import Callable, Iterator
from contextlib import contextmanager
from pathlib import Path
from typing import Any

# This process runs the suite in turn on the GPU, then task processes and Ray workers share it:
# allocate GPU memory as needed here too, not 75% of it up front (set before JAX starts).
os.environ.setdefault("XLA_PYTHON_CLIENT_PREALLOCATE", "false")

from openral_mjx.evaluation import RunSpec, evaluate
from openral_mjx.evaluation import cluster as ray_cluster
from openral_mjx.evaluation import suite as suite_module
from openral_mjx.report import EvalReport
from openral_mjx.scenes import make_scene, resolve_scene_backend


def powers_to(limit: int) -> list[int]:
    """1, 2, 4, ... up to `limit`, and `limit` itself."""
    out = [1]
    while out[-1] * 2 <= limit:
        out.append(out[-1] * 2)
    return out if out[-1] == limit else [*out, limit]


def gpu_count() -> int:
    import jax

    return sum(d.platform == "gpu" for d in jax.devices())


def emit(out: Path | None, row: dict) -> None:
    print(json.dumps(row), flush=True)
    if out is not None:
        out.parent.mkdir(parents=True, exist_ok=True)
        with out.open("a") as f:
            f.write(json.dumps(row) + "\n")


@contextmanager
def ray_node(gpus: int, cpus: int) -> Iterator[Any]:
    """A one-node Ray cluster of `gpus` GPUs and `cpus` CPUs started in this process (the
    runtime environment `--cluster` gives its workers), shut down after the block."""
    ray = ray_cluster.require_ray()
    runtime_env = {
        "py_modules": [str(ray_cluster.PACKAGE)],
        "env_vars": {"XLA_PYTHON_CLIENT_PREALLOCATE": "false"},
    }
    ray.init(
        num_gpus=gpus,
        num_cpus=cpus,
        include_dashboard=False,
        log_to_driver=False,
        runtime_env=runtime_env,
    )
    try:
        yield ray
    finally:
        ray.shutdown()


def outcomes(report: EvalReport) -> list[tuple]:
    return [
        (e.metadata.get("task"), e.metadata["seed"], e.success, e.steps) for e in report.episodes
    ]


def timed(run: Callable[[], EvalReport]) -> tuple[EvalReport, float]:
    start = time.perf_counter()
    report = run()
    return report, time.perf_counter() - start


def row(part: str, mode: str, workers: int, report: EvalReport, wall: float, first: list) -> dict:
    return {
        "part": part,
        "mode": mode,
        "workers": workers,
        "wall_s": round(wall, 3),
        "run_s": round(report.run_s, 3),
        "compile_s": round(report.compile_s, 3),
        "episodes": report.n_episodes,
        "episodes_per_s_wall": round(report.n_episodes / wall, 3),
        "success_rate": report.success_rate,
        "same_outcomes_as_first": outcomes(report) == first if first else True,
        "device": report.device,
    }


def suite_part(a: argparse.Namespace) -> list[dict]:
    """The suite one task at a time, with K task processes, and over Ray with K workers."""
    if a.first_tasks:  # only the suite's first tasks (a small check); Ray workers and task
        # processes are given task names, so patching the driver's lookup is enough
        full = suite_module.scene_suite
        suite_module.scene_suite = lambda scene, suite: full(scene, suite)[: a.first_tasks]
    backend = resolve_scene_backend(a.scene, a.backend)  # what Ray asks a GPU for
    spec = RunSpec(
        backend=backend,
        n_envs=a.n_envs,
        n_episodes=a.n_episodes,
        max_steps=a.max_steps,
        threads=1 if backend == "c" else None,
    )
    gpus = gpu_count()
    workers = a.workers or powers_to(gpus or os.cpu_count() or 1)
    args = (a.scene, a.suite, a.policy, spec)
    rows: list[dict] = []
    first: list = []

    def record(mode: str, k: int, run: Callable[[], EvalReport]) -> None:
        report, wall = timed(run)
        rows.append(row("suite", mode, k, report, wall, first))
        first[:] = first or outcomes(report)
        emit(a.out, rows[-1])

    record("in turn", 1, lambda: suite_module.evaluate_suite(*args))
    for k in workers:
        if k > 1:
            record(
                "task processes",
                k,
                lambda k=k: suite_module.evaluate_suite(*args, task_processes=k),
            )
        with ray_node(gpus=min(k, gpus), cpus=k if not gpus else max(k, os.cpu_count() or 1)):
            record("ray", k, lambda: suite_module.evaluate_suite(*args, cluster="local"))
    return rows


def host_part(a: argparse.Namespace) -> list[dict]:
    """The host scene's eval with K local worker processes, then with K Ray actors."""
    workers = a.host_workers or powers_to(os.cpu_count() or 1)
    options = {"task": a.host_task}
    rows: list[dict] = []
    first: list = []

    def run(k: int, ray: Any = None) -> EvalReport:
        scene = make_scene(a.host_scene, {**options, "n_workers": k})
        try:
            if ray is not None:
                scene.on_ray(ray)
            return evaluate(scene, "random", n_envs=a.host_n, max_steps=a.host_steps, seed=0)
        finally:
            scene.close()

    for k in workers:
        for mode in ("local workers", "ray actors"):
            if mode == "ray actors":
                with ray_node(gpus=0, cpus=k) as ray:
                    report, wall = timed(lambda k=k, ray=ray: run(k, ray))
            else:
                report, wall = timed(lambda k=k: run(k))
            rows.append(row("host", mode, k, report, wall, first))
            first[:] = first or outcomes(report)
            emit(a.out, rows[-1])
    return rows


def table(rows: list[dict]) -> str:
    lines = [
        f"{'part':6s} {'mode':15s} {'K':>4s} {'wall s':>9s} {'run s':>9s} {'compile s':>10s} "
        f"{'episodes/s':>11s} {'x first':>8s} same"
    ]
    base: dict[str, float] = {}
    for r in rows:
        base.setdefault(r["part"], r["wall_s"])
        lines.append(
            f"{r['part']:6s} {r['mode']:15s} {r['workers']:4d} {r['wall_s']:9.2f} "
            f"{r['run_s']:9.2f} {r['compile_s']:10.2f} {r['episodes_per_s_wall']:11.2f} "
            f"{base[r['part']] / r['wall_s']:8.2f} {'yes' if r['same_outcomes_as_first'] else 'NO'}"
        )
    return "\n".join(lines)


def main() -> int:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--parts", nargs="+", choices=("suite", "host"), default=["suite", "host"])
    p.add_argument("--scene", default="metaworld_mjx")
    p.add_argument("--suite", default="mt10")
    p.add_argument("--policy", default="metaworld-expert")
    p.add_argument("--backend", default="auto")
    p.add_argument("--n-envs", type=int, default=1000)
    p.add_argument("--n-episodes", type=int, default=1000)
    p.add_argument("--max-steps", type=int)
    p.add_argument("--first-tasks", type=int, help="only the suite's first N tasks")
    p.add_argument("--workers", type=int, nargs="+", help="default 1, 2, 4, ... GPUs (or cores)")
    p.add_argument("--host-scene", default="libero")
    p.add_argument("--host-task", default="libero_spatial/0")
    p.add_argument("--host-n", type=int, default=32, help="host envs (episodes) per run")
    p.add_argument("--host-steps", type=int, default=100)
    p.add_argument("--host-workers", type=int, nargs="+", help="default 1, 2, 4, ... cores")
    p.add_argument("--out", type=Path, help="JSON rows appended here")
    a = p.parse_args()
    meta = {
        "machine": f"{platform.node()} {os.cpu_count()} cpus, load {os.getloadavg()}",
        "command": " ".join([sys.executable, *sys.argv]),
    }
    emit(a.out, meta)
    rows = []
    if "suite" in a.parts:
        rows += suite_part(a)
    if "host" in a.parts:
        rows += host_part(a)
    print(table(rows))
    return 0 if all(r["same_outcomes_as_first"] for r in rows) else 1


if __name__ == "__main__":
    sys.exit(main())
