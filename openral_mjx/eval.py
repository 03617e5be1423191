"""`python -m openral_mjx.eval`: success rate with a confidence interval, throughput, a report.

Example: ``python -m openral_mjx.eval --scene tabletop_push --n-envs 1024``.
"""

from __future__ import annotations

import contextlib
import dataclasses
import datetime as dt
import re
import sys
from pathlib import Path

import tyro
from rich.progress import BarColumn, MofNCompleteColumn, Progress, TextColumn, TimeElapsedColumn

from openral_mjx.cli.common import command_line, guarded, stderr
from openral_mjx.core.errors import ConfigError
from openral_mjx.core.options import load_yaml, parse_overrides
from openral_mjx.evaluation import Evaluation, build_scene, run_evaluation
from openral_mjx.evaluation.frames import check_frames, record_frames, save_frames
from openral_mjx.evaluation.replay import choose_seeds, trace_episodes
from openral_mjx.evaluation.suite import evaluate_suite, format_tasks
from openral_mjx.physics import BACKEND_NAMES
from openral_mjx.policies import POLICIES
from openral_mjx.report import EvalReport, load_report, save_report
from openral_mjx.robots import ROBOTS
from openral_mjx.runner import processes
from openral_mjx.runner.compile_cache import enable_compilation_cache
from openral_mjx.scenes import SCENES, check_robot, resolve_scene_backend, scene_suite
from openral_mjx.stats.breakdown import format_breakdown
from openral_mjx.stats.report_comparison import compare_reports, format_comparison
from openral_mjx.viz import require_viz
from openral_mjx.viz.gl import GLUnavailable, camera_id, gl_backend
from openral_mjx.viz.plots import write_plots
from openral_mjx.viz.video import default_camera, write_episode_video


@dataclasses.dataclass
class EvalArgs:
    """Evaluate a policy on a MuJoCo scene over many seeds at once."""

    scene: str = "tabletop_push"
    """Scene ID (see --list)."""
    policy: str = "scripted"
    """Policy ID, or ID:ARG (see --list)."""
    task: str | None = None
    """Task of a multi-task scene (libero: SUITE/INDEX, e.g. libero_spatial/0; robosuite: Lift)."""
    suite: str | None = None
    """Evaluate every task of a suite (libero: libero_spatial, libero_object, libero_goal,
    libero_10, libero_90); reports per-task rates and their average."""
    robot: str | None = None
    """Registered robot for robot-agnostic scenes (default: the scene's, so101)."""
    robot_mjcf: Path | None = None
    """Your own robot MJCF (position actuators; end-effector site set by --opt ee_site=NAME)."""
    backend: str = "auto"
    """Physics backend: auto (warp with warp-lang on a CUDA GPU, mjx on another accelerator,
    else c), mjx, warp or c."""
    n_envs: int = 1024
    """Envs rolled out in parallel (one seed each)."""
    n_episodes: int | None = None
    """Total episodes (seeds); default n_envs. Runs in chunks of n_envs."""
    target_halfwidth: float | None = None
    """Sequential: run chunks of n_envs seeds until the 95% interval's half-width is <= this."""
    max_episodes: int | None = None
    """Cap on a sequential run's episodes (default: enough for any success rate)."""
    max_steps: int | None = None
    """Control steps per episode (default: the scene's)."""
    seed: int = 0
    """First seed; episodes use seeds seed .. seed+n_episodes-1."""
    config: Path | None = None
    """YAML file of scene options (see configs/)."""
    opt: tuple[str, ...] = ()
    """Scene option overrides, KEY=VALUE (after --config)."""
    threads: int | None = None
    """Threads of the C backend (default: all cores)."""
    contacts_per_env: int | None = None
    """Contact buffer per env of the warp backend (default 32); overflowing envs count as
    diverged."""
    devices: int | None = None
    """Shard envs over at most this many local devices (default: every GPU for mjx/warp)."""
    processes: int = 1
    """Run as this many processes on this host, each driving an equal share of the GPUs, as one
    job (jax.distributed): on warp, one process per GPU scales where one process for all does
    not (see README)."""
    out: Path | None = None
    """Report path (default: results/SCENE_POLICY_TIMESTAMP.json)."""
    factor_bins: int = 5
    """Equal-count bins per episode factor in the report's success breakdown."""
    breakdown: bool = True
    """Print the success breakdown by episode factor."""
    compare_with: Path | None = None
    """A report of the same scene to compare this run with (paired by seed where shared)."""
    video: int = 0
    """Write MP4s of the first K episodes (re-simulated after the run) to REPORT_videos/."""
    video_failures: int = 0
    """Write MP4s of the first K failed episodes too."""
    video_camera: str | None = None
    """Camera the videos show (default: the scene's choice)."""
    plots: bool = False
    """Write PNG plots beside the report: success by factor, episode lengths, reward curves."""
    frames: int = 0
    """Save the sensor readings (depth, RGB, laser) of the first K episodes at every step
    (re-simulated after the run) to REPORT.frames.npz; the scene must observe sensors (its
    obs_* options)."""
    compile_cache: bool = True
    """Use JAX's persistent compilation cache (~/.cache/openral_mjx/jax)."""
    list: bool = False
    """List scenes, policies, robots and backends, then exit."""


def _listing() -> str:
    return "\n".join(
        [
            f"scenes:   {', '.join(SCENES.names())}",
            f"policies: {', '.join(POLICIES.names())}",
            f"robots:   {', '.join(ROBOTS.names())}",
            f"backends: {', '.join(BACKEND_NAMES)} (MuJoCo scenes), host (host scenes)",
        ]
    )


def _scene_options(args: EvalArgs) -> dict:
    check_robot(args.scene, args.robot, args.robot_mjcf)
    options: dict = {}
    if args.config is not None:
        options.update(load_yaml(args.config))
    options.update(parse_overrides(args.opt))
    if args.task is not None:
        options["task"] = args.task
    if args.robot is not None:
        ROBOTS.get(args.robot)
        options["robot"] = args.robot
    if args.robot_mjcf is not None:
        if not args.robot_mjcf.is_file():
            raise ConfigError(f"robot MJCF {str(args.robot_mjcf)!r} does not exist")
        options["robot_mjcf"] = str(args.robot_mjcf)
    return options


def _reproduce(args: EvalArgs, backend: str, out: Path) -> str:
    argv = [
        "--scene",
        args.scene,
        "--policy",
        args.policy,
        "--backend",
        backend,
        "--n-envs",
        str(args.n_envs),
        "--seed",
        str(args.seed),
        "--out",
        str(out),
    ]
    for flag, value in (
        ("--task", args.task),
        ("--suite", args.suite),
        ("--n-episodes", args.n_episodes),
        ("--target-halfwidth", args.target_halfwidth),
        ("--max-episodes", args.max_episodes),
        ("--max-steps", args.max_steps),
        ("--robot", args.robot),
        ("--robot-mjcf", args.robot_mjcf),
        ("--config", args.config),
        ("--threads", args.threads),
        ("--contacts-per-env", args.contacts_per_env),
        ("--devices", args.devices),
        ("--processes", args.processes if args.processes != 1 else None),
        ("--factor-bins", args.factor_bins if args.factor_bins != 5 else None),
        ("--frames", args.frames or None),
    ):
        if value is not None:
            argv += [flag, str(value)]
    if args.opt:
        argv += ["--opt", *args.opt]
    return command_line("openral_mjx.eval", argv)


def run(args: EvalArgs) -> int:
    if args.list:
        print(_listing())
        return 0
    SCENES.get(args.scene)
    POLICIES.get(args.policy.partition(":")[0])
    if args.processes != 1 and processes.rank() is None:
        _check_processes(args)
        return processes.launch("openral_mjx.eval", sys.argv[1:], args.processes)
    processes.initialize()
    backend = resolve_scene_backend(args.scene, args.backend)
    options = _scene_options(args)
    stamp = dt.datetime.now().strftime("%Y%m%d-%H%M%S")
    policy_tag = re.sub(r"[^A-Za-z0-9_.-]+", "-", args.policy).strip("-")  # mlp:a/b: mlp-a-b
    out = args.out or Path("results") / f"{args.scene}_{policy_tag}_{stamp}.json"
    if out.exists() and out.is_dir():
        raise ConfigError(f"--out {str(out)!r} is a directory; give a file path")
    baseline = None
    if args.compare_with is not None:
        baseline = load_report(args.compare_with)
        if baseline.scene != args.scene:
            raise ConfigError(
                f"reports are not comparable: scene {baseline.scene!r} ({args.compare_with}) "
                f"vs {args.scene!r}"
            )
    if min(args.video, args.video_failures) < 0:
        raise ConfigError(
            f"--video and --video-failures must be >= 0, got {args.video}, {args.video_failures}"
        )
    want_video = args.video > 0 or args.video_failures > 0
    if want_video or args.plots:
        require_viz()
    if (want_video or args.frames) and backend == "host":
        raise ConfigError(
            f"--video and --frames re-simulate episodes in MuJoCo; scene {args.scene!r} runs in "
            "host workers: drop --video/--video-failures/--frames (--plots works)"
        )
    if args.suite is not None:
        _check_suite(args, want_video)
    command = _reproduce(args, backend, out)
    with contextlib.ExitStack() as owned:  # worker processes and policy servers end with the run
        evaluation, camera, gl, no_gl = None, "", "", None
        if args.suite is None:
            scene = build_scene(
                args.scene,
                options,
                backend=backend,
                n_envs=args.n_envs,
                threads=args.threads,
                contacts_per_env=args.contacts_per_env,
                devices=args.devices,
            )
            owned.callback(scene.close)
            check_frames(scene, args.frames)
            n_gpus = sum(d.platform == "gpu" for d in scene.backend.devices())
            if backend == "warp" and n_gpus > 1 and processes.rank() is None:
                stderr.print(
                    f"note: one process drives {n_gpus} GPUs on warp at ~1.5x one GPU; "
                    f"--processes {n_gpus} runs one process per GPU (~1.8-1.9x)"
                )
            if want_video:
                camera, gl, no_gl = _video_setup(args, scene)
        if args.compile_cache:
            enable_compilation_cache()

        with Progress(
            TextColumn("{task.description}"),
            BarColumn(),
            MofNCompleteColumn(),
            TimeElapsedColumn(),
            console=stderr,
            transient=True,
            disable=not processes.is_primary(),
        ) as progress:
            task = progress.add_task(f"compiling {args.scene} on {backend}", total=None)

            def on_chunk(done: int, total: int) -> None:
                progress.update(task, description="episodes", completed=done, total=total)

            if args.suite is not None:
                report = _run_suite(args, options, command, progress, task)
            else:
                evaluation = run_evaluation(
                    scene,
                    args.policy,
                    n_envs=args.n_envs,
                    n_episodes=args.n_episodes,
                    target_halfwidth=args.target_halfwidth,
                    max_episodes=args.max_episodes,
                    factor_bins=args.factor_bins,
                    seed=args.seed,
                    max_steps=args.max_steps,
                    backend=backend,
                    command=command,
                    on_chunk=on_chunk,
                    step_rewards=args.plots,
                )
                owned.enter_context(evaluation)
                report = evaluation.report
        stem = out.with_suffix("")
        frames_file = out.with_name(f"{stem.name}.frames.npz")
        if args.frames and evaluation is not None:
            with stderr.status(f"re-simulating {min(args.frames, report.n_episodes)} episode(s)"):
                arrays = record_frames(evaluation, args.frames, frames_file.name)
            save_frames(frames_file, arrays)
        if not processes.is_primary():
            processes.finish()
            return 0  # process 0 of the job writes and prints
        save_report(report, out)
        _print_results(args, report, baseline, out, frames_file if args.frames else None)
        if args.plots and evaluation is not None:
            for path in write_plots(report, stem, evaluation.arrays["rewards"]):
                print(f"plot: {path}")
        if want_video and evaluation is not None:
            if no_gl is not None:
                raise GLUnavailable(f"cannot render videos: {no_gl}")
            write_videos(evaluation, args, stem.with_name(f"{stem.name}_videos"), camera, gl)
    processes.finish()
    return 0


def _check_processes(args: EvalArgs) -> None:
    """What a job of several processes cannot do, refused before any starts."""
    processes.check_count(args.processes)
    if args.backend not in ("mjx", "warp"):
        raise ConfigError(
            f"--processes {args.processes} shards envs over GPUs: give --backend mjx or warp, "
            f"not {args.backend!r}"
        )
    extras = [
        flag
        for flag, on in (
            ("--suite", args.suite is not None),
            ("--video", args.video > 0),
            ("--video-failures", args.video_failures > 0),
            ("--frames", args.frames > 0),
            ("--plots", args.plots),
            ("--devices", args.devices is not None),
        )
        if on
    ]
    if extras:
        raise ConfigError(f"--processes {args.processes} does not combine with {', '.join(extras)}")


def _video_setup(args: EvalArgs, scene) -> tuple[str, str, GLUnavailable | None]:
    """The videos' camera and GL backend, checked before anything runs (no GL is reported
    after the run, which still writes its report)."""
    camera = args.video_camera or default_camera(scene)
    camera_id(scene.mj_model, camera)
    try:
        return camera, gl_backend(), None
    except GLUnavailable as e:
        return camera, "", e


def _print_results(
    args: EvalArgs, report: EvalReport, baseline, out: Path, frames_file: Path | None
) -> None:
    print(report.summary())
    if args.suite is not None:
        print(format_tasks(report))
    if report.n_envs < min(args.n_envs, report.n_episodes):
        print(
            f"note: ran {report.n_envs} envs at a time: --n-envs {args.n_envs} would not fit "
            "in device memory",
            file=sys.stderr,
        )
    if report.sequential is not None:
        print(sequential_summary(report))
    if args.breakdown and report.breakdown:
        print(format_breakdown(report.breakdown, report.confidence))
    if baseline is not None:
        rc = compare_reports(baseline, report)
        print(format_comparison(rc, baseline, report, (str(args.compare_with), str(out))))
    if frames_file is not None:
        print(f"frames: {frames_file}")
    print(f"report: {out}")


def _check_suite(args: EvalArgs, want_video: bool) -> None:
    """`--suite` runs every task of the suite with a fixed episode count and no videos, plots
    or frames."""
    if args.task is not None or args.target_halfwidth is not None:
        raise ConfigError("--suite runs every task of the suite: drop --task/--target-halfwidth")
    if want_video or args.plots or args.frames:
        raise ConfigError("--suite writes one report over its tasks: drop --video/--plots/--frames")
    scene_suite(args.scene, args.suite)  # validate before starting anything


def _run_suite(args: EvalArgs, options: dict, command: str, progress: Progress, task) -> EvalReport:
    """Every task of `--suite`, one after another, into one report."""

    def on_task(i: int, n: int, name: str) -> None:
        progress.update(task, description=f"task {i + 1}/{n} {name}", completed=0, total=None)

    def on_chunk(done: int, total: int) -> None:
        progress.update(task, completed=done, total=total)

    return evaluate_suite(
        args.scene,
        args.suite,
        args.policy,
        n_envs=args.n_envs,
        n_episodes=args.n_episodes,
        seed=args.seed,
        max_steps=args.max_steps,
        options=options,
        command=command,
        on_task=on_task,
        on_chunk=on_chunk,
    )


def write_videos(
    evaluation: Evaluation, args: EvalArgs, folder: Path, camera: str, gl: str
) -> None:
    """Re-simulate the chosen episodes and write one MP4 each into `folder`."""
    seeds = choose_seeds(evaluation, args.video, args.video_failures)
    failed = int((~evaluation.arrays["success"]).sum())
    if failed < args.video_failures:
        print(f"note: {failed} failed episode(s) to film, not {args.video_failures}")
    with stderr.status(f"re-simulating {len(seeds)} episode(s) for videos"):
        traces = trace_episodes(evaluation, seeds)
    for trace in traces:
        path = folder / f"seed{trace.seed}_{trace.outcome}.mp4"
        with stderr.status(f"rendering {path.name}"):
            write_episode_video(path, evaluation.scene, args.policy, trace, camera=camera, gl=gl)
        note = "" if trace.reproduced else "; re-simulation DIFFERS from the evaluated episode"
        print(f"video: {path} ({trace.outcome} at step {trace.steps}{note})")


def sequential_summary(report: EvalReport) -> str:
    """One line on how a sequential run stopped."""
    s = report.sequential
    assert s is not None
    why = (
        f"half-width {s.halfwidth:.4f} (target {s.target_halfwidth:g})"
        if s.stopped == "target"
        else f"reached --max-episodes before the target {s.target_halfwidth:g}: half-width "
        f"{s.halfwidth:.4f}"
    )
    return (
        f"sequential: stopped after {s.looks} chunk(s) of {s.chunk:,}, {report.n_episodes:,} "
        f"of at most {s.max_episodes:,} episodes; {why}; interval exact under this stopping rule"
    )


def main() -> None:
    args = tyro.cli(EvalArgs, prog="python -m openral_mjx.eval")
    raise SystemExit(guarded(lambda: run(args)))


if __name__ == "__main__":
    main()
