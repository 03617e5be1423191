"""Evaluator throughput against raw physics ceilings, measured side by side in one process.

Per batch size N, on the same scene model and substeps:

* evaluator: the full runner (scripted policy, scene logic) in control steps/s;
* raw ceiling of the scene's backend: for `mjx`/`warp`, a bare `vmap(scan(mjx.step x
  substeps))` with the same implementation and buffers; for `c`, bare `mujoco.rollout` calls
  (one per control step, same threads) with no JAX;
* MuJoCo C on all cores (`mujoco.rollout`), the CPU reference.

The raw runs replay the evaluator's recorded actions open-loop from the same reset states, so
they simulate the same contacts (the solvers exit early on easy states: a resting arm would
flatter the ceiling about twofold).
"""

from __future__ import annotations

import time
from collections.abc import Callable
from typing import Any

import jax
import jax.numpy as jnp
import mujoco
import numpy as np
from mujoco import rollout

from openral_mjx.policies import make_policy
from openral_mjx.runner import run_seeds
from openral_mjx.scenes import Scene


def raw_mjx(scene: Scene, actions: np.ndarray) -> tuple[float, float]:
    """Bare `vmap(scan(mjx.step))` (the scene backend's MJX implementation) replaying the
    evaluator's actions open-loop from the same reset states (so contacts and solver work
    match): (compile s, control steps/s)."""
    from openral_mjx.physics.mjx_backend import mjx

    mx, n_sub = scene.backend.mx, scene.options.n_substeps
    n, steps = actions.shape[:2]
    keys = jax.vmap(lambda s: jax.random.split(jax.random.PRNGKey(s))[0])(jnp.arange(n))
    data = jax.jit(jax.vmap(lambda k: scene.reset(k).physics.data))(keys)
    low, high = scene.action_bounds()
    ctrls = jnp.clip(jnp.asarray(actions), low, high)

    def one(d, ctrl_seq):
        def control_step(d, ctrl):
            d = d.replace(ctrl=ctrl)
            return jax.lax.fori_loop(0, n_sub, lambda _, x: mjx.step(mx, x), d), None

        return jax.lax.scan(control_step, d, ctrl_seq)[0].qpos

    fn = jax.jit(jax.vmap(one))
    t = time.perf_counter()
    compiled = fn.lower(data, ctrls).compile()
    compile_s = time.perf_counter() - t
    t = time.perf_counter()
    jax.block_until_ready(compiled(data, ctrls))
    return compile_s, n * steps / (time.perf_counter() - t)


def raw_c(scene: Scene, actions: np.ndarray, threads: int) -> float:
    """Bare `mujoco.rollout`, one call per control step as the evaluator makes, replaying the
    evaluator's actions from the same reset states, no JAX: control steps/s."""
    n, steps = actions.shape[:2]
    keys = jax.vmap(lambda s: jax.random.split(jax.random.PRNGKey(s))[0])(jnp.arange(n))
    with jax.default_device(jax.devices("cpu")[0]):
        bits = jax.jit(jax.vmap(lambda k: scene.reset(k).physics.data))(keys)
    states = np.asarray(bits).view(np.float64).reshape(n, -1)
    low, high = (np.asarray(x, np.float64) for x in scene.action_bounds())
    ctrl = np.clip(np.asarray(actions, np.float64), low, high)
    c_model = scene.backend.host_model
    datas = [mujoco.MjData(c_model) for _ in range(threads)]
    with rollout.Rollout(nthread=threads) as pool:
        t = time.perf_counter()
        for i in range(steps):
            out, _ = pool.rollout(
                c_model, datas, states, ctrl[:, i : i + 1], nstep=scene.options.n_substeps
            )
            states = out[:, -1]
        return n * steps / (time.perf_counter() - t)


def peak_memory_bytes() -> int | None:
    stats = jax.devices()[0].memory_stats() or {}
    return stats.get("peak_bytes_in_use")


def measure_throughput(
    scene: Scene,
    c_scene: Scene,
    ns: tuple[int, ...],
    max_steps: int,
    threads: int,
    c_max_envs: int,
    log: Callable[[str], None] = print,
) -> list[dict[str, Any]]:
    """Per batch size N, side by side: the evaluator (scripted policy) in control steps/s,
    the raw ceiling of `scene`'s backend on the evaluator's recorded actions, and MuJoCo C
    (`c_scene`, `threads` threads, at most `c_max_envs` envs); with their ratios."""
    backend = scene.backend.name
    policy = make_policy("scripted", scene)
    rows = []
    for n in ns:
        arrays, timing = run_seeds(
            scene,
            policy,
            None,
            seeds=np.arange(n),
            n_envs=n,
            max_steps=max_steps,
            record=("actions",),
        )
        evaluator = n * max_steps / timing.run_s
        row = {"n": n, "evaluator_steps_per_s": evaluator, "evaluator_compile_s": timing.compile_s}
        if backend in ("mjx", "warp"):
            row["raw_compile_s"], row["raw_steps_per_s"] = raw_mjx(scene, arrays["actions"])
            row["peak_device_bytes"] = peak_memory_bytes()
        n_c = min(n, c_max_envs)
        row["c_envs"], row["c_threads"] = n_c, threads
        row["c_steps_per_s"] = raw_c(c_scene, arrays["actions"][:n_c], threads)
        if backend == "c":
            row["raw_steps_per_s"] = row["c_steps_per_s"]
        row["evaluator_over_raw"] = evaluator / row["raw_steps_per_s"]
        row["evaluator_over_c"] = evaluator / row["c_steps_per_s"]
        rows.append(row)
        log(
            f"N={n:>6}: evaluator {evaluator:>12,.0f}  raw {backend} "
            f"{row['raw_steps_per_s']:>12,.0f}  C({threads} thr) {row['c_steps_per_s']:>10,.0f}"
            f"  control steps/s | eval/raw {row['evaluator_over_raw']:.2f}"
            f"  eval/C {row['evaluator_over_c']:.2f}  compile {timing.compile_s:.1f} s"
        )
    return rows
