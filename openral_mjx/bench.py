"""`python -m openral_mjx.bench`: evaluator throughput against raw physics ceilings, one run
(`--rays`: the ray-cast sensors against raw `mjx.ray` and `mj_multiRay`, see `bench_rays`).

Per batch size N, on the same scene model and substeps, measured side by side:

* evaluator: the full runner (scripted policy, scene logic, freezing) in control steps/s;
* raw ceiling of the chosen backend: for `mjx`/`warp`, a bare `vmap(scan(mjx.step x
  substeps))` with the same implementation and buffers; for `c`, bare `mujoco.rollout` calls
  (one per control step, same threads) with no JAX;
* MuJoCo C on all cores (`mujoco.rollout`), the CPU reference.

The raw runs replay the evaluator's recorded actions open-loop from the same reset states, so
they simulate the same contacts (the solvers exit early on easy states: a resting arm would
flatter the ceiling about twofold).

Ratios (evaluator / raw, evaluator / C) are what transfers between machines; absolute numbers
count only with the device named. Prints a table and writes JSON (`--out`).
"""

from __future__ import annotations

import dataclasses
import datetime as dt
import time
from pathlib import Path

import jax
import jax.numpy as jnp
import mujoco
import numpy as np
import tyro
from mujoco import rollout

from openral_mjx.cli_common import command_line, guarded
from openral_mjx.compile_cache import enable_compilation_cache
from openral_mjx.errors import ConfigError
from openral_mjx.evaluate import device_description, package_versions
from openral_mjx.physics import PhysicsSettings, resolve_backend_name
from openral_mjx.physics.c_backend import default_threads
from openral_mjx.policies import make_policy
from openral_mjx.rollout import run_seeds
from openral_mjx.scenes import make_scene
from openral_mjx.schema import write_json_atomic


@dataclasses.dataclass
class BenchArgs:
    """Measure evaluator throughput against the raw physics ceilings."""

    scene: str = "tabletop_push"
    """Scene ID."""
    backend: str = "auto"
    """auto, mjx, warp or c."""
    n: tuple[int, ...] = (1024,)
    """Batch sizes to measure."""
    max_steps: int | None = None
    """Control steps per rollout (default: the scene's episode length)."""
    c_max_envs: int = 4096
    """Cap on envs for the MuJoCo C reference (its rate does not depend on N past the cores)."""
    threads: int | None = None
    """Threads for MuJoCo C (default: all cores)."""
    contacts_per_env: int = PhysicsSettings.contacts_per_env
    """Contact buffer per env of the warp backend."""
    out: Path = Path("results/bench.json")
    compile_cache: bool = True
    rays: bool = False
    """Measure the ray-cast sensors (laser, depth) in rays/s instead of the evaluator, against
    vmap(mjx.ray) and mj_multiRay on all cores, on the default JAX device (see
    openral_mjx/bench_rays.py; --backend and --max-steps do not apply)."""
    laser_frame: str = "ee"
    """--rays: body or site carrying the benchmarked laser."""
    camera: str | None = None
    """--rays: camera of the benchmarked depth images (default: the scene's first)."""
    geom_counts: tuple[int, ...] = (8, 16, 32, 64)
    """--rays: scene sizes (geoms) of the cost-versus-geom-count sweep."""
    repeats: int = 5
    """--rays: timed calls per measurement (median)."""


def raw_mjx(scene, actions: np.ndarray) -> tuple[float, float]:
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


def raw_c(scene, actions: np.ndarray, threads: int) -> float:
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


def run_rays_bench(args: BenchArgs) -> int:
    """`--rays`: sensor rays/s against raw `mjx.ray` and `mj_multiRay` (bench_rays)."""
    from openral_mjx.bench_rays import run_rays

    if not args.n or min(args.n) < 1 or args.repeats < 1 or min(args.geom_counts, default=2) < 2:
        raise ConfigError(
            f"--n, --repeats must be positive and --geom-counts >= 2, got {args.n}, "
            f"{args.repeats}, {args.geom_counts}"
        )
    if args.compile_cache:
        enable_compilation_cache()
    threads = args.threads or default_threads()
    scene = make_scene(args.scene, backend="c", settings=PhysicsSettings(threads=threads))
    result = run_rays(
        scene,
        args.n,
        laser_frame=args.laser_frame,
        camera=args.camera,
        geom_counts=args.geom_counts,
        threads=threads,
        repeats=args.repeats,
        log=lambda line: print(line, flush=True),
    )
    device = jax.devices()[0]
    argv = ["--rays", "--scene", args.scene, "--n", *map(str, args.n), "--laser-frame"]
    argv += [args.laser_frame, "--geom-counts", *map(str, args.geom_counts)]
    argv += ["--repeats", str(args.repeats), "--threads", str(threads)]
    if args.camera:
        argv += ["--camera", args.camera]
    write_json_atomic(
        args.out,
        {
            "scene": args.scene,
            "device": f"{device.platform}: {device.device_kind}",
            **result,
            "versions": package_versions(),
            "created_at": dt.datetime.now(dt.UTC).isoformat(timespec="seconds"),
            "command": command_line("openral_mjx.bench", argv),
        },
    )
    print(f"results: {args.out}")
    return 0


def run(args: BenchArgs) -> int:
    if args.rays:
        return run_rays_bench(args)
    backend = resolve_backend_name(args.backend)
    if not args.n or min(args.n) < 1 or (args.max_steps is not None and args.max_steps < 1):
        raise ConfigError(
            f"--n values and --max-steps must be positive, got {args.n}, {args.max_steps}"
        )
    if args.compile_cache:
        enable_compilation_cache()
    threads = args.threads or default_threads()
    settings = PhysicsSettings(
        threads=threads, batch_size=max(args.n), contacts_per_env=args.contacts_per_env
    )
    scene = make_scene(args.scene, backend=backend, settings=settings)
    args = dataclasses.replace(args, max_steps=args.max_steps or scene.max_steps)
    policy = make_policy("scripted", scene)
    c_scene = scene if backend == "c" else make_scene(args.scene, backend="c", settings=settings)
    rows = []
    for n in args.n:
        arrays, timing = run_seeds(
            scene,
            policy,
            None,
            seeds=np.arange(n),
            n_envs=n,
            max_steps=args.max_steps,
            record=("actions",),
        )
        evaluator = n * args.max_steps / timing.run_s
        row = {"n": n, "evaluator_steps_per_s": evaluator, "evaluator_compile_s": timing.compile_s}
        if backend in ("mjx", "warp"):
            row["raw_compile_s"], row["raw_steps_per_s"] = raw_mjx(scene, arrays["actions"])
            row["peak_device_bytes"] = peak_memory_bytes()
        n_c = min(n, args.c_max_envs)
        row["c_envs"], row["c_threads"] = n_c, threads
        row["c_steps_per_s"] = raw_c(c_scene, arrays["actions"][:n_c], threads)
        if backend == "c":
            row["raw_steps_per_s"] = row["c_steps_per_s"]
        row["evaluator_over_raw"] = evaluator / row["raw_steps_per_s"]
        row["evaluator_over_c"] = evaluator / row["c_steps_per_s"]
        rows.append(row)
        print(
            f"N={n:>6}: evaluator {evaluator:>12,.0f}  raw {backend} "
            f"{row['raw_steps_per_s']:>12,.0f}  C({threads} thr) {row['c_steps_per_s']:>10,.0f}"
            f"  control steps/s | eval/raw {row['evaluator_over_raw']:.2f}"
            f"  eval/C {row['evaluator_over_c']:.2f}  compile {timing.compile_s:.1f} s",
            flush=True,
        )
    result = {
        "scene": args.scene,
        "backend": backend,
        "device": device_description(scene),
        "max_steps": args.max_steps,
        "n_substeps": scene.options.n_substeps,
        "timestep": scene.options.timestep,
        "rows": rows,
        "versions": package_versions(),
        "created_at": dt.datetime.now(dt.UTC).isoformat(timespec="seconds"),
        "command": command_line(
            "openral_mjx.bench",
            [
                "--scene",
                args.scene,
                "--backend",
                backend,
                "--n",
                *map(str, args.n),
                "--max-steps",
                str(args.max_steps),
            ],
        ),
    }
    write_json_atomic(args.out, result)
    print(f"results: {args.out}")
    return 0


def main() -> None:
    args = tyro.cli(BenchArgs, prog="python -m openral_mjx.bench")
    raise SystemExit(guarded(lambda: run(args)))


if __name__ == "__main__":
    main()
