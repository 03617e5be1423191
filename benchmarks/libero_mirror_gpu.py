"""The LIBERO mirror's speed on one GPU: evaluator against raw physics, per task and batch size.

Per task (one per suite by default) and batch size N, in one process, side by side:

- evaluator: `libero-expert` on `libero_mjx` through the runner (fixed chunks, `--steps`
  control steps from seeds 0..N-1), in control steps/s. Its time includes each episode's
  reset: LIBERO's 10 settle steps, physics as long as 10 control steps, which the count does
  not credit (a user's episode runs up to 220-520 steps; `--steps` runs 30 by default);
- raw physics, replayed (``raw``): bare ``vmap(scan(scan(25 x mjx.step)))`` with the scene's
  own MJX model, buffers and per-env fixtures, from the same initial states, applying at every
  physics step the control the evaluator's episode applied there (recorded by
  `LiberoMjx.reset_controls` and `step_controls` in a run not timed): the same physics, the
  settle steps included, credited the same `--steps` control steps. It has no controller,
  observation, goal, policy or runner, so ``evaluator / raw`` is what all of those cost.
  ``replay_qpos_max_error``: how far the replay's last joint positions are from the recorded
  episode's (0 where it is the same trajectory);
- raw physics, held (``raw_held``, the figure of 2026-11-27 to 2026-12-01): the same bare loop
  from the settled reset states, holding each env's last reset control for `--steps` control
  steps, no settle. The arm stays near its pose where the expert moves it through contacts,
  so it is not the same physics; it is kept beside the replay to show by how much.

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
from openral_mjx.physics import WARP_GRAPHS, release_warp_graphs
from openral_mjx.physics.mjx_backend import mjx
from openral_mjx.policies import make_policy
from openral_mjx.runner import run_seeds
from openral_mjx.runner.compile_cache import enable_compilation_cache
from openral_mjx.runner.episode import control_step, policy_state0, seed_keys
from openral_mjx.scenes import scene_options, scene_settings

TASKS = ("libero_spatial/0", "libero_object/0", "libero_goal/1", "libero_10/0")


def raw_held(scene, n: int, steps: int) -> tuple[float, float, float]:
    """(compile s, control steps/s, share of envs whose state stayed finite) of bare MJX
    holding the settled reset controls."""
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

    compile_s, rate, finite = _timed(jax.jit(jax.vmap(one)), (data,), n * steps)
    return compile_s, rate, float(np.asarray(finite).mean())


def recorded_controls(scene, policy, n: int, steps: int):
    """The controls the expert's episodes of seeds 0..n-1 apply at every physics step, the
    settle steps first: ``(n, 10 + steps, n_substeps, nu)``, their last joint positions, and
    whether each env's episode stayed whole (a diverged env is parked, the replay is not)."""

    def run(seeds):
        init = seeds % scene.n_init_states
        policy_keys = seed_keys(seeds)[1]
        state, settle = jax.vmap(scene.reset_controls)(init)
        pstate = policy_state0(policy, state.obs, n)

        def body(carry, t):  # the runner's control step, recording the controls
            state, pstate = carry
            (state, ctrls), pstate, _ = control_step(
                scene, policy, None, state, pstate, policy_keys, t, step=scene.step_controls
            )
            return (state, pstate), ctrls

        (last, _), ctrls = jax.lax.scan(body, (state, pstate), jnp.arange(steps))
        ctrls = jnp.concatenate([settle, jnp.swapaxes(ctrls, 0, 1)], axis=1)
        return ctrls, last.physics.data.qpos, last.physics.quantities.ok

    return jax.block_until_ready(jax.jit(run)(jnp.arange(n, dtype=jnp.int32)))


def raw_replay(
    scene, n: int, steps: int, ctrls, qpos_end, whole
) -> tuple[float, float, float, float]:
    """(compile s, control steps/s, share of envs whose state stayed finite, the replay's
    largest joint-position difference from the recorded episodes that stayed `whole`) of
    bare MJX replaying `ctrls` from the initial states (settle steps included, `steps`
    credited)."""
    init = jnp.arange(n, dtype=jnp.int32) % scene.n_init_states
    start = jax.jit(jax.vmap(scene.initial_physics))(init)

    def one(d, fields, u):
        mx = scene.backend.model(fields)

        def control_step(d, u_step):
            physics_step = lambda d, u_i: (mjx.step(mx, d.replace(ctrl=u_i)), None)  # noqa: E731
            return jax.lax.scan(physics_step, d, u_step)[0], None

        return jax.lax.scan(control_step, d, u)[0].qpos

    compile_s, rate, qpos = _timed(
        jax.jit(jax.vmap(one)), (start.data, start.fields, ctrls), n * steps
    )
    qpos = np.asarray(qpos)
    finite = np.all(np.isfinite(qpos), axis=1)
    whole = np.asarray(whole)
    error = float(np.nanmax(np.abs(qpos - np.asarray(qpos_end))[whole])) if whole.any() else None
    return compile_s, rate, float(finite.mean()), error


def _peak_gb() -> float | None:
    """The JAX allocator's peak bytes in use on the first device so far, in GB."""
    stats = jax.devices()[0].memory_stats() or {}
    peak = stats.get("peak_bytes_in_use")
    return None if peak is None else round(peak / 1e9, 2)


def _timed(fn, args: tuple, credited: int):
    """(compile s, `credited` control steps per second of one run, its output) of `fn`."""
    t = time.perf_counter()
    compiled = fn.lower(*args).compile()
    compile_s = time.perf_counter() - t
    t = time.perf_counter()
    out = jax.block_until_ready(compiled(*args))
    return compile_s, credited / (time.perf_counter() - t), out


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--tasks", nargs="+", default=list(TASKS))
    ap.add_argument("--ns", nargs="+", type=int, default=[4096, 16384])
    ap.add_argument("--steps", type=int, default=40)
    ap.add_argument("--backend", default="warp")
    ap.add_argument("--contacts-per-env", type=int, default=None)
    ap.add_argument("--ccd-contacts-per-env", type=int, default=None)
    ap.add_argument(
        "--warp-graphs",
        choices=sorted(WARP_GRAPHS),
        default=None,
        help="Warp's CUDA-graph mode (PhysicsSettings.warp_graphs; default: MJX's)",
    )
    ap.add_argument(
        "--evaluator-only",
        action="store_true",
        help="time the evaluator alone (no replay, no held run): one compile, not three",
    )
    ap.add_argument(
        "--skip-held", action="store_true", help="leave out the held raw run (raw_held_*)"
    )
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
            warp_graphs=a.warp_graphs,
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
            # the process's peak so far (JAX keeps no per-row peak): with --ns ascending, the
            # row of the largest batch holds that batch's peak
            row["peak_gpu_gb_so_far"] = _peak_gb()
            rows.append(row)
            print(json.dumps(row), flush=True)
            out = {"device": str(jax.devices()[0].device_kind), "rows": rows}
            with open(a.out, "w") as f:  # after every row: a run cut short keeps its rows
                json.dump(out, f, indent=1)


def measure(scene, policy, task: str, n: int, a: argparse.Namespace) -> dict:
    """One row: evaluator and raw physics of `task` at `n` envs."""
    arrays, timing = run_seeds(scene, policy, None, seeds=np.arange(n), n_envs=n, max_steps=a.steps)
    evaluator = timing.n_envs * timing.scan_steps / timing.run_s
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
        "warp_graphs": scene.backend.settings.warp_graphs,
    }
    if a.evaluator_only:
        return row
    # each run's program holds Warp's graphs of its own buffers: 4.6 GB apiece at 16,384 envs
    # with 128 CCD slots, which left the replay no room (2026-12-02)
    release_warp_graphs()
    ctrls, qpos_end, whole = recorded_controls(scene, policy, n, a.steps)
    release_warp_graphs()
    try:
        raw_compile, raw, finite, error = raw_replay(scene, n, a.steps, ctrls, qpos_end, whole)
    except Exception as e:  # out of memory at this size: keep the evaluator's figures
        return row | {"raw_error": str(e)[:300]}
    del ctrls
    release_warp_graphs()
    row |= {
        "raw_compile_s": round(raw_compile, 1),
        "raw_steps_per_s": round(raw),
        "raw_finite_share": finite,
        "replay_qpos_max_error": error,
        "evaluator_over_raw": round(evaluator / raw, 3),
    }
    if a.skip_held:
        return row
    held_compile, held, held_finite = raw_held(scene, n, a.steps)
    row |= {
        "raw_held_compile_s": round(held_compile, 1),
        "raw_held_steps_per_s": round(held),
        "raw_held_finite_share": held_finite,
        "evaluator_over_raw_held": round(evaluator / held, 3),
    }
    return row


if __name__ == "__main__":
    main()
