"""The mirror against MetaWorld itself: same initial states, same physics, same outcomes.

MetaWorld runs unchanged in worker processes of its own environment (`worker_env`);
every comparison puts it on the mirror's initial state by handing it the mirror's random vector
(MetaWorld's frozen-vector reset), so both build the episode the same way:

- **initial state**: the largest difference between the two reset observations;
- **physics**: from the mirror's exact reset joint state (handed to MetaWorld too), the same
  open-loop action sequence (uniform in [-1, 1], 100 steps); the largest distance over the
  100 steps between the hands, and between the first objects, in the observations;
- **outcome**: MetaWorld's scripted expert closed loop in both (on the mirror through
  `metaworld-expert`), per seed: success within the episode, the agreement of the two, the
  exact McNemar test on the discordant seeds, both rates with Wilson intervals.

``python -m openral_mjx.benchmarks.metaworld.agreement --tasks push-v3 --backend c`` prints the
agreement table (markdown) and writes it as JSON with ``--out``.
"""

from __future__ import annotations

import argparse
import concurrent.futures
import contextlib
import json
import math
import os
import sys
import tempfile
from collections.abc import Iterator, Sequence
from pathlib import Path
from typing import Any

import jax
import numpy as np

from openral_mjx.benchmarks.metaworld.mirror.scene import MetaWorldMjx
from openral_mjx.core.errors import ConfigError
from openral_mjx.core.files import write_text_atomic
from openral_mjx.host.envs import ensure_env, our_mujoco_path
from openral_mjx.host.pool import Worker
from openral_mjx.runner.episode import seed_keys
from openral_mjx.scenes import make_scene
from openral_mjx.stats import mcnemar_exact_pvalue, wilson_interval

ENV = "metaworld"
FACTORY = "openral_mjx.benchmarks.metaworld.worker_env:make"
TIMEOUT_S = 600.0


# Which MuJoCo MetaWorld's code runs on: its pinned one (3.3.0, in its own environment), or
# this process's (the mirror's engine) put first on the worker's path. The second separates the
# mirror's task logic, which must then agree exactly, from the engine version.
ENGINES = ("metaworld", "ours")


@contextlib.contextmanager
def host_workers(task: str, n: int, engine: str = "metaworld") -> Iterator[list[Worker]]:
    """`n` worker processes, each holding MetaWorld's env for `task` on `engine`'s MuJoCo
    (closed on exit)."""
    if engine not in ENGINES:
        raise ConfigError(f"unknown MetaWorld engine {engine!r}; valid: {', '.join(ENGINES)}")
    python = ensure_env(ENV)
    logs = Path(tempfile.mkdtemp(prefix="openral_mjx_agreement_"))
    first = [our_mujoco_path(python)] if engine == "ours" else []
    workers: list[Worker] = []
    try:
        for i in range(n):
            log = logs / f"worker{i}.log"
            workers.append(Worker(python, {}, log, name=f"metaworld {i}", path_first=first))
        init = {"op": "init", "factory": FACTORY, "kwargs": {"task": task}}
        # built side by side: each start imports MetaWorld and compiles its model (~2 s)
        with concurrent.futures.ThreadPoolExecutor(n) as pool:
            list(pool.map(lambda w: w.call(init, TIMEOUT_S), workers))
        yield workers
    finally:
        for w in workers:
            w.close()


def host_versions(workers: Sequence[Worker]) -> dict[str, str]:
    """The MetaWorld and MuJoCo versions the workers run."""
    return workers[0].call({"op": "call", "method": "versions", "kwargs": {}}, TIMEOUT_S)


def host_rollouts(workers: Sequence[Worker], calls: Sequence[dict[str, Any]]) -> list[dict]:
    """`rollout(**kwargs)` for each of `calls`, spread over the workers (results in order)."""
    chunks = [list(range(i, len(calls), len(workers))) for i in range(len(workers))]

    def run(w: int) -> list[tuple[int, dict]]:
        msg = {"op": "call", "method": "rollout"}
        return [(i, workers[w].call({**msg, "kwargs": calls[i]}, TIMEOUT_S)) for i in chunks[w]]

    out: list[Any] = [None] * len(calls)
    with concurrent.futures.ThreadPoolExecutor(len(workers)) as pool:
        for part in pool.map(run, range(len(workers))):
            for i, r in part:
                out[i] = r
    return out


def mirror_resets(scene: MetaWorldMjx, seeds: np.ndarray) -> Any:
    """The batched reset states of `seeds` (as the runner builds them)."""
    seeds = np.asarray(seeds, np.int32)
    return jax.jit(jax.vmap(scene.reset_with_seed))(seeds, seed_keys(seeds)[0])


def trajectory_agreement(
    scene: MetaWorldMjx, workers: Sequence[Worker], seeds: np.ndarray, steps: int = 100
) -> dict[str, np.ndarray]:
    """Per seed: reset observation difference (max |.|), then the largest hand and object
    distance over `steps` open-loop random actions from the mirror's reset joint state."""
    state = mirror_resets(scene, seeds)
    n = len(seeds)
    key = jax.random.PRNGKey(12345)
    actions = np.asarray(jax.random.uniform(key, (steps, n, 4), minval=-1.0, maxval=1.0))
    step = jax.jit(jax.vmap(scene.step))
    obs = [np.asarray(state.obs, np.float64)]
    reset_obs = obs[0]
    q = state.physics.quantities
    qpos, qvel = np.asarray(q.qpos, np.float64), np.asarray(q.qvel, np.float64)
    vecs = np.asarray(state.info["vec"], np.float64)
    s = state
    for t in range(steps):
        s = step(s, actions[t])
        obs.append(np.asarray(s.obs, np.float64))
    mirror = np.stack(obs, axis=1)  # (n, steps + 1, 39)
    fresh = host_rollouts(
        workers, [{"rand_vec": v, "actions": actions[:0, i]} for i, v in enumerate(vecs)]
    )
    same = host_rollouts(
        workers,
        [
            {"rand_vec": vecs[i], "actions": actions[:, i], "qpos": qpos[i], "qvel": qvel[i]}
            for i in range(n)
        ],
    )
    # the physics from step 1 on: a reset observation may show the state before placement
    # (`observes_before_place`), and MetaWorld set to a joint state observes it afresh
    host = np.stack([r["obs"] for r in same])[:, 1:]
    mirror = mirror[:, 1:]
    return {
        "reset": np.array([np.abs(f["obs"][0] - reset_obs[i]).max() for i, f in enumerate(fresh)]),
        "hand": np.linalg.norm(host[:, :, :3] - mirror[:, :, :3], axis=-1).max(axis=1),
        "object": np.linalg.norm(host[:, :, 4:7] - mirror[:, :, 4:7], axis=-1).max(axis=1),
    }


def outcome_agreement(
    scene: MetaWorldMjx, workers: Sequence[Worker], seeds: np.ndarray, n_envs: int = 256
) -> dict[str, Any]:
    """Per-seed success of MetaWorld's scripted expert on the mirror and on MetaWorld."""
    from openral_mjx.evaluation.run import run_evaluation

    seeds = np.asarray(seeds)
    with run_evaluation(
        scene,
        "metaworld-expert",
        n_envs=min(n_envs, len(seeds)),
        n_episodes=len(seeds),
        seed=int(seeds[0]),
        batching="chunks",
    ) as ev:
        mirror = np.asarray(ev.arrays["success"], bool)
        mirror_steps = np.asarray(ev.arrays["first_success_step"], np.int64)
        ran = np.asarray(ev.seeds)
    vecs = np.asarray(mirror_resets(scene, ran).info["vec"], np.float64)
    results = host_rollouts(workers, [{"rand_vec": v, "max_steps": scene.max_steps} for v in vecs])
    host = np.array([r["first_success"] >= 0 for r in results])
    # the runner counts steps taken (success after step 1 is 1); `rollout` indexes from 0
    host_steps = np.array([r["first_success"] + 1 for r in results], np.int64)
    both = mirror & host
    only_m, only_h = int(np.sum(mirror & ~host)), int(np.sum(host & ~mirror))
    return {
        "seeds": ran,
        "mirror": mirror,
        "host": host,
        "mirror_steps": mirror_steps,
        "host_steps": host_steps,
        "steps_median_difference": (
            float(np.median(mirror_steps[both] - host_steps[both])) if both.any() else None
        ),
        "agreement": float(np.mean(mirror == host)),
        "mcnemar_p": float(mcnemar_exact_pvalue(only_m, only_h)),
        "mirror_rate": float(mirror.mean()),
        "host_rate": float(host.mean()),
        "mirror_ci": tuple(float(x) for x in wilson_interval(int(mirror.sum()), len(mirror))),
        "host_ci": tuple(float(x) for x in wilson_interval(int(host.sum()), len(host))),
    }


def task_row(
    task: str,
    backend: str,
    n_seeds: int,
    traj_seeds: int,
    workers: int,
    engine: str = "metaworld",
) -> dict[str, Any]:
    """The agreement table's row for `task` (seeds 0..n_seeds-1; 0..traj_seeds-1 for physics),
    MetaWorld running on `engine`'s MuJoCo."""
    scene = make_scene("metaworld_mjx", {"task": task}, backend=backend)
    try:
        with host_workers(task, workers, engine) as pool:
            versions = host_versions(pool)
            traj = trajectory_agreement(scene, pool, np.arange(traj_seeds))
            out = outcome_agreement(scene, pool, np.arange(n_seeds)) if n_seeds else None
    finally:
        scene.close()
    row: dict[str, Any] = {
        "task": task,
        "backend": backend,
        "metaworld": versions["metaworld"],
        "metaworld_mujoco": versions["mujoco"],
        "reset_obs_max": float(traj["reset"].max()),
        "hand_max_m": float(traj["hand"].max()),
        "object_max_m": float(traj["object"].max()),
    }
    if out is not None:
        arrays = ("seeds", "mirror", "host", "mirror_steps", "host_steps")
        row.update({k: v for k, v in out.items() if k not in arrays})
        row["n_seeds"] = len(out["seeds"])
    return row


def markdown(rows: Sequence[dict[str, Any]]) -> str:
    head = (
        "| task | backend | reset obs | hand (m) | object (m) | seeds | per-seed agreement "
        "| McNemar p | mirror rate | MetaWorld rate |\n|---|---|---|---|---|---|---|---|---|---|"
    )
    lines = [head]
    for r in rows:
        if "agreement" in r:
            m_lo, m_hi = r["mirror_ci"]
            h_lo, h_hi = r["host_ci"]
            tail = (
                f"{r['n_seeds']} | {100 * r['agreement']:.1f}% | {r['mcnemar_p']:.3g} | "
                f"{100 * r['mirror_rate']:.1f}% [{100 * m_lo:.1f}, {100 * m_hi:.1f}] | "
                f"{100 * r['host_rate']:.1f}% [{100 * h_lo:.1f}, {100 * h_hi:.1f}]"
            )
        else:
            tail = "- | - | - | - | -"
        lines.append(
            f"| {r['task']} | {r['backend']} | {r['reset_obs_max']:.2e} | {r['hand_max_m']:.2e} "
            f"| {r['object_max_m']:.2e} | {tail} |"
        )
    return "\n".join(lines)


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--tasks", nargs="+", required=True)
    parser.add_argument("--backend", default="c")
    parser.add_argument("--seeds", type=int, default=500, help="closed-loop seeds per task")
    parser.add_argument("--traj-seeds", type=int, default=8, help="open-loop seeds per task")
    parser.add_argument("--workers", type=int, default=os.cpu_count() or 1)
    parser.add_argument(
        "--engine",
        choices=ENGINES,
        default="metaworld",
        help="the MuJoCo MetaWorld runs on: its pinned one, or ours (this process's)",
    )
    parser.add_argument("--out", type=Path)
    args = parser.parse_args(argv)
    rows = []
    for task in args.tasks:
        row = task_row(task, args.backend, args.seeds, args.traj_seeds, args.workers, args.engine)
        rows.append(row)
        print(markdown(rows[-1:]).splitlines()[-1], file=sys.stderr, flush=True)
    print(markdown(rows))
    if args.out:
        write_text_atomic(args.out, json.dumps(rows, indent=2, default=_plain))
    return 0


def _plain(x: Any) -> Any:
    if isinstance(x, np.generic):
        return x.item()
    if isinstance(x, float) and math.isnan(x):
        return None
    raise TypeError(type(x))


if __name__ == "__main__":
    raise SystemExit(main())
