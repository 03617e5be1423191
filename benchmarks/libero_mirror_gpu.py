"""The LIBERO mirror's speed on one GPU: evaluator against raw physics, per task and batch size.

Per task (one per suite by default) and batch size N, in one process, side by side:

- evaluator: `libero-expert` on `libero_mjx` through the runner (fixed chunks, `--steps`
  control steps from seeds 0..N-1), in control steps/s;
- raw physics: bare ``vmap(scan(fori_loop(25, mjx.step)))`` with the scene's own MJX model and
  buffers, from the same reset states, holding each env's last reset control (the OSC
  torques and gripper command the settle steps ended on), in control steps/s. It has no
  controller, observation or goal, so ``evaluator / raw`` is what all of those cost. The
  held controls keep the arm near its pose; the evaluator's expert moves it, so the raw
  run's contacts are not the same (the solver may exit sooner or later on either).

Usage (GPU machine, after ``source benchmarks/gpu_setup.sh``; the task exports carried in
``OPENRAL_MJX_LIBERO_MODELS``):

    python3 benchmarks/libero_mirror_gpu.py --ns 4096 16384 --steps 40 --out $OUT/speed.json

``--backend mjx`` (MJX's JAX implementation, which the scene does not register: its control
step compiles for over 15 minutes on a CPU) builds the scene class directly, to measure its
compile and speed on a GPU.
"""

from __future__ import annotations

import argparse
import json
import time

import jax
import jax.numpy as jnp
import numpy as np

from openral_mjx.benchmarks.libero.mirror import LiberoMjx
from openral_mjx.physics.mjx_backend import mjx
from openral_mjx.policies import make_policy
from openral_mjx.runner import run_seeds
from openral_mjx.runner.compile_cache import enable_compilation_cache
from openral_mjx.scenes import scene_options, scene_settings

TASKS = ("libero_spatial/0", "libero_object/0", "libero_goal/1", "libero_10/0")


def raw_physics(scene, n: int, steps: int) -> tuple[float, float, float]:
    """(compile s, control steps/s, share of envs whose state stayed finite) of bare MJX."""
    mx, n_sub = scene.backend.mx, scene.n_substeps
    states = jax.jit(jax.vmap(scene.reset_with_seed))(
        jnp.arange(n, dtype=jnp.int32), jax.vmap(jax.random.PRNGKey)(jnp.arange(n))
    )
    data = states.physics.data

    def one(d):
        def control_step(d, _):
            return jax.lax.fori_loop(0, n_sub, lambda _, x: mjx.step(mx, x), d), None

        d = jax.lax.scan(control_step, d, None, length=steps)[0]
        return jnp.all(jnp.isfinite(d.qpos))

    fn = jax.jit(jax.vmap(one))
    t = time.perf_counter()
    compiled = fn.lower(data).compile()
    compile_s = time.perf_counter() - t
    t = time.perf_counter()
    finite = np.asarray(jax.block_until_ready(compiled(data)))
    return compile_s, n * steps / (time.perf_counter() - t), float(finite.mean())


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--tasks", nargs="+", default=list(TASKS))
    ap.add_argument("--ns", nargs="+", type=int, default=[4096, 16384])
    ap.add_argument("--steps", type=int, default=40)
    ap.add_argument("--backend", default="warp")
    ap.add_argument("--contacts-per-env", type=int, default=None)
    ap.add_argument("--ccd-contacts-per-env", type=int, default=None)
    ap.add_argument("--out", required=True)
    a = ap.parse_args()
    enable_compilation_cache()
    rows = []
    for task in a.tasks:
        t = time.perf_counter()
        settings = scene_settings(
            "libero_mjx",
            a.contacts_per_env,
            batch_size=max(a.ns),
            ccd_contacts_per_env=a.ccd_contacts_per_env,
        )
        options = scene_options("libero_mjx", {"task": task})
        scene = LiberoMjx(options, backend=a.backend, settings=settings)
        build_s = time.perf_counter() - t
        policy = make_policy("libero-expert", scene)
        for n in a.ns:
            try:
                row = measure(scene, policy, task, n, a)
            except Exception as e:  # an OOM at one size keeps the other sizes' rows
                row = {"task": task, "backend": a.backend, "n_envs": n, "error": str(e)[:300]}
            row["build_s"] = round(build_s, 1)
            rows.append(row)
            print(json.dumps(row), flush=True)
            out = {"device": str(jax.devices()[0].device_kind), "rows": rows}
            with open(a.out, "w") as f:  # after every row: a run cut short keeps its rows
                json.dump(out, f, indent=1)


def measure(scene, policy, task: str, n: int, a: argparse.Namespace) -> dict:
    """One row: evaluator and raw physics of `task` at `n` envs."""
    arrays, timing = run_seeds(scene, policy, None, seeds=np.arange(n), n_envs=n, max_steps=a.steps)
    evaluator = timing.n_envs * timing.scan_steps / timing.run_s
    raw_compile, raw, finite = raw_physics(scene, n, a.steps)
    row = {
        "task": task,
        "backend": a.backend,
        "n_envs": n,
        "steps": a.steps,
        "evaluator_compile_s": round(timing.compile_s, 1),
        "evaluator_steps_per_s": round(evaluator),
        "evaluator_diverged": int(np.asarray(arrays["diverged"]).sum()),
        "contacts_per_env": scene.backend.settings.contacts_per_env,
        "ccd_contacts_per_env": scene.backend.settings.ccd_contacts_per_env,
        "raw_compile_s": round(raw_compile, 1),
        "raw_steps_per_s": round(raw),
        "raw_finite_share": finite,
        "evaluator_over_raw": round(evaluator / raw, 3),
    }
    return row


if __name__ == "__main__":
    main()
