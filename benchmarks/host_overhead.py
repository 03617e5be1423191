"""Host adapter overhead and worker scaling on LIBERO, MetaWorld, PushT, ALOHA or ManiSkill3
(CPU), in one process and one run (`--scene libero`, `metaworld`, `pusht`, `aloha` or
`maniskill`).

1. Reference: N envs reset and stepped from a plain Python loop in one process of the
   worker environment (`host_direct_loop.py`).
2. The adapter with one worker holding the same N envs (the same sequential work, plus the
   jitted loop, the callbacks and the pipes): overhead = its time / the reference's - 1.
   On a shared machine the two runs see different loads, so the adapter also measures, in the
   same run, the time its worker spent inside the envs' own code: the in-run overhead is the
   chunk's wall time over that, minus 1.
3. The adapter with 1, 2, ... workers: scaling (runs interleaved with the reference).
4. With `--direct-workers 1 2 ...`: the reference also as K plain loops side by side (K
   processes, N/K envs each, clocks started together once all have built their envs; wall
   time = the slowest loop's), the same work K adapter workers do.
Timings cover the reset of all N envs and `--steps` control steps (env construction is not
timed in either). Policy: uniform random actions in the scene's bounds (ALOHA: zero joint
targets, see `policy`). A scene with episode factors (MetaWorld, PushT, ALOHA, ManiSkill3) resets
its envs once more after the chunk to read them: the reference loop does the same. Prints and
optionally writes JSON.

    python benchmarks/host_overhead.py --n 4 --steps 20 --workers 1 2 4 --out bench.json
    python benchmarks/host_overhead.py --scene metaworld --task push-v3 --image-size 0 \
        --n 8 --steps 100 --workers 1 2
    python benchmarks/host_overhead.py --scene pusht --task PushT-v0 --image-size 96 \
        --n 16 --steps 100 --workers 1 2
    python benchmarks/host_overhead.py --scene aloha --task AlohaTransferCube-v0 \
        --image-size 480 --n 2 --steps 20 --workers 1 2
    python benchmarks/host_overhead.py --scene maniskill --task PushCube-v1 --image-size 0 \
        --n 32 --steps 50 --workers 1 2 --direct-workers 1 2 --repeats 3
"""

from __future__ import annotations

import argparse
import json
import os
import platform
import subprocess
import sys
import tempfile
from pathlib import Path

from openral_mjx.evaluation import evaluate
from openral_mjx.host.envs import ensure_env
from openral_mjx.host.pool import _shim_dir
from openral_mjx.scenes import make_scene

# scene -> (worker environment, env factory, action size, extra factory kwargs / scene options,
# resets per run: the episode's, plus one for the factors where the scene has them)
SCENES = {
    "libero": ("lerobot-libero", "openral_mjx.benchmarks.libero.worker_env:LiberoEnv", 7, {}, 1),
    "metaworld": (
        "metaworld",
        "openral_mjx.benchmarks.metaworld.worker_env:make",
        4,
        {"expert": False},
        2,
    ),
    "pusht": ("gym-envs", "openral_mjx.benchmarks.pusht.worker_env:make", 2, {}, 2),
    "aloha": ("gym-envs", "openral_mjx.benchmarks.aloha.worker_env:make", 14, {}, 2),
    "maniskill": ("maniskill", "openral_mjx.benchmarks.maniskill.worker_env:make", 8, {}, 2),
}
# scene -> the environment variables its scene sets in its workers (the reference loop's too)
WORKER_ENV = {"maniskill": {"OMP_NUM_THREADS": "1"}}


def image_options(scene: str, image_size: int) -> dict:
    """`--image-size` as the scene's options: ALOHA's camera is `image_size` high and 4/3 of
    that wide (lerobot's 480 x 640 at 480; 0: no camera). ManiSkill3 has no camera (none)."""
    if scene == "maniskill":
        return {}
    if scene == "aloha":
        return {"image_height": image_size, "image_width": image_size * 4 // 3}
    return {"image_size": image_size}


def policy(scene: str) -> str:
    """Uniform random actions; on ALOHA zero joint targets (random targets over the whole joint
    ranges blow its physics up within tens of steps, ending those episodes early)."""
    return "zero" if scene == "aloha" else "random"


def bounds(scene: str, task: str) -> tuple[list[float], list[float]]:
    """The range the policy's actions are drawn from (the reference loop draws from it too)."""
    if policy(scene) == "zero":
        n = SCENES[scene][2]
        return [0.0] * n, [0.0] * n
    s = make_scene(scene, {"task": task, **image_options(scene, 8)})
    try:
        low, high = s.action_bounds()
    finally:
        s.close()
    return [float(v) for v in low], [float(v) for v in high]


def direct(
    scene: str, task: str, image_size: int, n: int, steps: int, repeats: int, procs: int = 1
) -> list[dict]:
    """The reference: one plain loop over the N envs, or with `procs` > 1 that many loops side
    by side over N/procs envs each (as the adapter splits them), started together; `total_s`
    is then the slowest loop's, and `loops` holds each loop's result."""
    env_name, factory, action_size, extra, resets = SCENES[scene]
    python = ensure_env(env_name)
    env = {**os.environ, "PYTHONPATH": _shim_dir(), "MUJOCO_GL": "egl", "PYOPENGL_PLATFORM": "egl"}
    env |= {"SDL_VIDEODRIVER": "dummy", "PYGAME_HIDE_SUPPORT_PROMPT": "1"}
    env |= WORKER_ENV.get(scene, {})
    script = Path(__file__).with_name("host_direct_loop.py")
    kwargs = json.dumps({"task": task, **image_options(scene, image_size), **extra})
    low, high = bounds(scene, task)
    cuts = [round(n * k / procs) for k in range(procs + 1)]  # the adapter's split of the envs
    out = []
    for _ in range(repeats):
        with tempfile.TemporaryDirectory() as barrier:
            running = []
            for k in range(procs):
                argv = [python, str(script), "--factory", factory, "--kwargs", kwargs]
                argv += ["--n", str(cuts[k + 1] - cuts[k]), "--seed0", str(cuts[k])]
                argv += ["--steps", str(steps), "--action-size", str(action_size)]
                argv += ["--resets", str(resets), "--bounds", json.dumps([low, high])]
                if procs > 1:
                    argv += ["--barrier", barrier, "--procs", str(procs)]
                running.append(subprocess.Popen(argv, env=env, stdout=subprocess.PIPE, text=True))
            loops = []
            for proc in running:
                stdout, _ = proc.communicate()
                if proc.returncode:
                    raise subprocess.CalledProcessError(proc.returncode, proc.args)
                loops.append(json.loads(stdout.strip().splitlines()[-1]))
        if procs == 1:
            out.append({**loops[0], "procs": 1})
        else:
            total = max(r["total_s"] for r in loops)
            out.append({"n": n, "steps": steps, "procs": procs, "total_s": total, "loops": loops})
    return out


def adapter(scene_name: str, task: str, image_size: int, n: int, steps: int, workers: int) -> dict:
    """One adapter run; `env_busy_s` is each worker's time inside the envs' own reset/step
    code during the run (from the moment it is compiled), so `total_s / max(env_busy_s) - 1`
    is what the adapter adds, measured in-run."""
    extra = SCENES[scene_name][3]
    options = {"task": task, **image_options(scene_name, image_size), "n_workers": workers}
    options |= extra
    scene = make_scene(scene_name, options)
    start: list[float] = []

    def compiled(done: int, total: int, successes: int) -> None:
        if done == 0:  # compiled, nothing run yet
            start.extend(scene.batch.busy_total_s)

    try:
        report = evaluate(scene, policy(scene_name), n_envs=n, max_steps=steps, on_chunk=compiled)
        busy = [b - s for b, s in zip(scene.batch.busy_total_s, start, strict=True)]
    finally:
        scene.close()
    return {
        "workers": workers,
        "total_s": report.run_s,
        "setup_s": report.compile_s,
        "env_busy_s": busy,
        "in_run_overhead": report.run_s / max(busy) - 1,
    }


def main() -> None:
    p = argparse.ArgumentParser()
    p.add_argument("--scene", choices=sorted(SCENES), default="libero")
    p.add_argument("--task", default="libero_spatial/0")
    p.add_argument("--image-size", type=int, default=128)
    p.add_argument("--n", type=int, default=4)
    p.add_argument("--steps", type=int, default=20)
    p.add_argument("--workers", type=int, nargs="+", default=[1, 2, 4])
    p.add_argument("--direct-workers", type=int, nargs="+", default=[1])
    p.add_argument("--repeats", type=int, default=2)
    p.add_argument("--out", type=Path)
    a = p.parse_args()
    ref, runs = [], []
    for _ in range(a.repeats):  # interleaved, so that a change of machine load hits all alike
        for k in a.direct_workers:
            ref += direct(a.scene, a.task, a.image_size, a.n, a.steps, 1, k)
        runs += [adapter(a.scene, a.task, a.image_size, a.n, a.steps, w) for w in a.workers]
    best_by_procs = {k: min(r["total_s"] for r in ref if r["procs"] == k) for k in a.direct_workers}
    best_ref = best_by_procs.get(1, float("nan"))
    best = {w: min(r["total_s"] for r in runs if r["workers"] == w) for w in a.workers}
    result = {
        "machine": f"{platform.node()} {os.cpu_count()} cpus, load {os.getloadavg()}",
        "scene": a.scene,
        "task": a.task,
        "image_size": a.image_size,
        "n_envs": a.n,
        "steps": a.steps,
        "direct_loop": ref,
        "adapter": runs,
        "best_direct_s": best_ref,
        "best_direct_s_by_workers": best_by_procs,
        "best_adapter_s": best,
        "overhead_1_worker_vs_direct_loop": best.get(1, float("nan")) / best_ref - 1,
        "in_run_overhead_1_worker": min(
            (r["in_run_overhead"] for r in runs if r["workers"] == 1), default=float("nan")
        ),
        "env_steps_per_s": {w: a.n * a.steps / s for w, s in best.items()},
        "episodes_per_s": {w: a.n / s for w, s in best.items()},
        "direct_episodes_per_s": {k: a.n / s for k, s in best_by_procs.items()},
        "command": " ".join([sys.executable, *sys.argv]),
    }
    text = json.dumps(result, indent=1)
    print(text)
    if a.out:
        a.out.write_text(text + "\n")


if __name__ == "__main__":
    main()
