"""`python -m openral_mjx.bench`: evaluator throughput against raw physics ceilings, one run
(`--rays`: the ray-cast sensors against raw `mjx.ray` and `mj_multiRay`; `--batching`:
continuous batching against fixed chunks in episodes/s).

What is measured and how: `openral_mjx.perf.throughput`, `openral_mjx.perf.rays` and
`openral_mjx.perf.batching`. Ratios
(evaluator / raw, evaluator / C) are what transfers between machines; absolute numbers count
only with the device named. Prints a table and writes JSON (`--out`).
"""

from __future__ import annotations

import dataclasses
import datetime as dt
from collections.abc import Sequence
from pathlib import Path

import jax
import tyro

from openral_mjx.cli.common import command_line, given_flags, guarded, parse
from openral_mjx.core.errors import ConfigError, unknown
from openral_mjx.core.files import check_writable, write_json_atomic
from openral_mjx.evaluation.provenance import device_description, package_versions
from openral_mjx.evaluation.spec import MAX_SETTING
from openral_mjx.perf.batching import compare_batching
from openral_mjx.perf.rays import run_rays
from openral_mjx.perf.throughput import measure_throughput
from openral_mjx.physics import BACKEND_NAMES, PhysicsSettings, resolve_backend_name
from openral_mjx.physics.base import check_warp_graphs
from openral_mjx.physics.c_backend import default_threads
from openral_mjx.runner import MAX_ENVS, MAX_EPISODES, MAX_STEPS, check_batching
from openral_mjx.runner.compile_cache import enable_compilation_cache
from openral_mjx.scenes import SCENES, make_scene, scene_settings


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
    contacts_per_env: int | None = None
    """Contact buffer per env of the warp backend (default: the scene's)."""
    ccd_contacts_per_env: int | None = None
    """Of those, how many may come from convex collision (GJK/EPA; default: all), as eval's."""
    warp_graphs: str | None = None
    """How warp replays its calls as CUDA graphs (warp, staged, none; default: MJX's), as
    eval's."""
    out: Path = Path("results/bench.json")
    compile_cache: bool = True
    rays: bool = False
    """Measure the ray-cast sensors (laser, depth) in rays/s instead of the evaluator, against
    vmap(mjx.ray) and mj_multiRay on all cores, on the default JAX device (see
    openral_mjx/perf/rays.py; --backend and --max-steps do not apply)."""
    laser_frame: str = "ee"
    """--rays: body or site carrying the benchmarked laser."""
    camera: str | None = None
    """--rays: camera of the benchmarked depth images (default: the scene's first)."""
    geom_counts: tuple[int, ...] = (8, 16, 32, 64)
    """--rays: scene sizes (geoms) of the cost-versus-geom-count sweep."""
    repeats: int = 5
    """--rays: timed calls per measurement (median)."""
    batching: bool = False
    """Measure continuous batching (refill) against fixed chunks at each --n: episodes/s,
    simulated and live env-steps/s, and the paired agreement of their outcomes (see
    openral_mjx/perf/batching.py)."""
    episodes: int = 65536
    """--batching: seeds per run."""
    chunk_episodes: int | None = None
    """--batching: seeds of the chunked reference (a multiple of every --n; default
    --episodes): chunks do the same work whatever the outcomes, so fewer give its rate."""
    refill_every: int = 1
    """--batching: control steps between batched resets."""
    policy: str = "scripted"
    """--batching: the policy evaluated."""


def run_rays_bench(args: BenchArgs) -> int:
    """`--rays`: sensor rays/s against raw `mjx.ray` and `mj_multiRay` (perf.rays)."""
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


def run_batching_bench(args: BenchArgs) -> int:
    """`--batching`: refill against chunks in episodes/s (perf.batching)."""
    backend = resolve_backend_name(args.backend)
    check_batching("refill", backend, args.refill_every)
    if not args.n or min(args.n) < 1 or args.episodes < max(args.n):
        raise ConfigError(f"--n must be positive and at most --episodes, got {args.n}")
    if args.compile_cache:
        enable_compilation_cache()
    settings = _settings(args, args.threads or default_threads())
    scene = make_scene(args.scene, backend=backend, settings=settings)
    rows = compare_batching(
        scene,
        args.policy,
        args.n,
        args.episodes,
        chunk_episodes=args.chunk_episodes,
        refill_every=args.refill_every,
        max_steps=args.max_steps,
        log=lambda line: print(line, flush=True),
    )
    argv = ["--batching", "--scene", args.scene, "--backend", backend, "--policy", args.policy]
    argv += ["--n", *map(str, args.n), "--episodes", str(args.episodes)]
    if args.chunk_episodes is not None:
        argv += ["--chunk-episodes", str(args.chunk_episodes)]
    if args.refill_every != 1:
        argv += ["--refill-every", str(args.refill_every)]
    if args.max_steps is not None:
        argv += ["--max-steps", str(args.max_steps)]
    argv += _warp_argv(args)
    write_json_atomic(
        args.out,
        {
            "scene": args.scene,
            "backend": backend,
            "device": device_description(scene),
            "policy": args.policy,
            "rows": rows,
            "versions": package_versions(),
            "created_at": dt.datetime.now(dt.UTC).isoformat(timespec="seconds"),
            "command": command_line("openral_mjx.bench", argv),
        },
    )
    print(f"results: {args.out}")
    return 0


def _settings(args: BenchArgs, threads: int) -> PhysicsSettings:
    """The scene's physics settings for batches up to the largest `--n`."""
    return scene_settings(
        args.scene,
        args.contacts_per_env,
        threads=threads,
        batch_size=max(args.n),
        ccd_contacts_per_env=args.ccd_contacts_per_env,
        warp_graphs=args.warp_graphs,
    )


def _warp_argv(args: BenchArgs) -> list[str]:
    """The warp buffer and graph flags given, for the recorded command."""
    return given_flags(
        (
            ("--contacts-per-env", args.contacts_per_env),
            ("--ccd-contacts-per-env", args.ccd_contacts_per_env),
            ("--warp-graphs", args.warp_graphs),
        )
    )


def validate(args: BenchArgs) -> None:
    """What every mode needs, checked before anything is built or measured: the output path
    (a run's results are not lost to a bad path afterwards) and the sizes that drive memory
    (each `ConfigError` names the flag and the value)."""
    SCENES.get(args.scene)
    if args.backend not in BACKEND_NAMES:
        raise unknown("backend", args.backend, BACKEND_NAMES)
    check_writable(args.out)
    bounds = (
        ("--n", args.n, MAX_ENVS),
        ("--c-max-envs", (args.c_max_envs,), MAX_ENVS),
        ("--episodes", (args.episodes,), MAX_EPISODES),
        ("--chunk-episodes", (args.chunk_episodes or 1,), MAX_EPISODES),
        ("--max-steps", (args.max_steps or 1,), MAX_STEPS),
        ("--repeats", (args.repeats,), 1000),
        ("--geom-counts", args.geom_counts, 4096),
        ("--threads", (args.threads or 1,), MAX_SETTING["threads"]),
        ("--contacts-per-env", (args.contacts_per_env or 1,), MAX_SETTING["contacts_per_env"]),
        (
            "--ccd-contacts-per-env",
            (args.ccd_contacts_per_env or 1,),
            MAX_SETTING["ccd_contacts_per_env"],
        ),
        ("--refill-every", (args.refill_every,), MAX_STEPS),
    )
    for flag, values, most in bounds:
        bad = [v for v in values if not 1 <= v <= most]
        if bad:
            raise ConfigError(f"{flag} must lie in [1, {most:,}], got {bad[0]}")
    check_warp_graphs(args.warp_graphs)


def run(args: BenchArgs) -> int:
    validate(args)
    if args.rays:
        return run_rays_bench(args)
    if args.batching:
        return run_batching_bench(args)
    backend = resolve_backend_name(args.backend)
    if not args.n or min(args.n) < 1 or (args.max_steps is not None and args.max_steps < 1):
        raise ConfigError(
            f"--n values and --max-steps must be positive, got {args.n}, {args.max_steps}"
        )
    if args.compile_cache:
        enable_compilation_cache()
    threads = args.threads or default_threads()
    settings = _settings(args, threads)
    scene = make_scene(args.scene, backend=backend, settings=settings)
    args = dataclasses.replace(args, max_steps=args.max_steps or scene.max_steps)
    c_scene = scene if backend == "c" else make_scene(args.scene, backend="c", settings=settings)
    rows = measure_throughput(
        scene,
        c_scene,
        args.n,
        args.max_steps,
        threads,
        args.c_max_envs,
        log=lambda line: print(line, flush=True),
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
                *_warp_argv(args),
            ],
        ),
    }
    write_json_atomic(args.out, result)
    print(f"results: {args.out}")
    return 0


def main(argv: Sequence[str] | None = None) -> None:
    """The command: `argv` (default: the process's arguments) -> exit code."""
    prog = "python -m openral_mjx.bench"
    args = parse(lambda: tyro.cli(BenchArgs, prog=prog, args=argv), prog)
    raise SystemExit(guarded(lambda: run(args)))


if __name__ == "__main__":
    main()
