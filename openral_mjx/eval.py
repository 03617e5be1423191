"""`python -m openral_mjx.eval`: success rate with a confidence interval, throughput, a report.

Example: ``python -m openral_mjx.eval --scene tabletop_push --n-envs 1024``.

The command is a pipeline of named steps, each a function of what the step before returned:
`validate` (every flag and option, the report path, before anything is built;
`openral_mjx.cli.eval_plan`, over the flags of `openral_mjx.cli.eval_args`) -> `build` (the
scene, the video renderer) -> `execute` (the evaluation, with a progress bar) -> `write`
(report, frames, plots, videos) -> `show` (the summary and where each file went, in the words
of `openral_mjx.cli.eval_text`). The work itself is the library's (`openral_mjx.evaluation`);
these modules parse, check and print.
"""

from __future__ import annotations

import contextlib
import dataclasses
import sys
from collections.abc import Callable, Sequence
from pathlib import Path

import tyro
from rich.progress import (
    BarColumn,
    MofNCompleteColumn,
    Progress,
    TaskID,
    TextColumn,
    TimeElapsedColumn,
)

from openral_mjx.cli.common import guarded, parse, stderr
from openral_mjx.cli.eval_args import EvalArgs
from openral_mjx.cli.eval_plan import EvalPlan, check_distributed, validate, writes_media
from openral_mjx.cli.eval_text import decision_summary, listing, sequential_summary, warnings_line
from openral_mjx.core.errors import ConfigError, RunFailed
from openral_mjx.core.interrupts import EXIT_CODES, signals_raise
from openral_mjx.evaluation import Evaluation, cluster
from openral_mjx.evaluation.frames import check_frames, record_frames, save_frames
from openral_mjx.evaluation.partial import Interrupted
from openral_mjx.evaluation.replay import EpisodeTrace, choose_seeds, trace_episodes
from openral_mjx.evaluation.run import build_spec_scene, evaluate_spec, policy_options, timed
from openral_mjx.evaluation.suite import evaluate_suite, format_tasks, mps_running
from openral_mjx.evaluation.sweep import SweepCluster, run_sweep
from openral_mjx.physics.gl import GLUnavailable, camera_id, gl_backend
from openral_mjx.physics.mj_warnings import count_warnings
from openral_mjx.report import EvalReport, save_report
from openral_mjx.report.sweep import SweepReport, save_sweep
from openral_mjx.runner import processes
from openral_mjx.runner.compile_cache import default_cache_dir, enable_compilation_cache
from openral_mjx.scenes import Scene, mirrored, seed_options
from openral_mjx.scenes.factor_ranges import parse_factors
from openral_mjx.scenes.host_scene import HostScene
from openral_mjx.stats import compare_reports, format_breakdown, format_comparison
from openral_mjx.viz.plots import save_png, sweep_curve, write_plots
from openral_mjx.viz.video import default_camera, write_episode_video

# ---- build -----------------------------------------------------------------------------------


@dataclasses.dataclass
class Built:
    """What `build` made for the run: the scene (None for a suite, which builds one per task)
    with the options it was built from and, for videos, the camera and the GL backend (or why
    there is none: the run still goes ahead and writes its report, and the missing renderer is
    reported at the end)."""

    scene: Scene | None = None
    options: dict = dataclasses.field(default_factory=dict)
    build_s: dict[str, float] = dataclasses.field(default_factory=dict)  # the report's
    camera: str = ""
    gl: str = ""
    no_gl: GLUnavailable | None = None


def build(plan: EvalPlan, owned: contextlib.ExitStack) -> Built:
    """Build the scene (its workers end with `owned`) and check what needs its model."""
    args = plan.args
    if args.compile_cache:
        enable_compilation_cache()
    if args.suite is not None:
        return Built()
    # a lerobot policy's cameras, unless --opt names them
    options = policy_options(args.scene, args.policy, plan.options)
    # a host scene's env workers as Ray actors: connected first, so they end before Ray does
    # (a sweep's points connect in `run_sweep`)
    actors = args.cluster is not None and args.sweep is None
    ray = owned.enter_context(cluster.connected(args.cluster)) if actors else None
    build_s: dict[str, float] = {}
    with timed(build_s, "scene"):
        scene = build_spec_scene(
            args.scene, options, plan.spec, randomize=args.randomize if args.sweep is None else ()
        )
    owned.callback(scene.close)
    if ray is not None:
        assert isinstance(scene, HostScene)  # validate: --cluster without --suite is a host scene
        scene.on_ray(ray)
    if plan.decide is not None and plan.baseline is not None and plan.baseline.task != scene.task:
        raise ConfigError(
            f"reports are not comparable: task {plan.baseline.task!r} ({args.compare_with}) vs "
            f"{scene.task!r}"
        )
    check_frames(scene, args.frames)
    n_gpus = sum(d.platform == "gpu" for d in scene.backend.devices())
    if plan.backend == "warp" and n_gpus > 1 and processes.rank() is None:
        stderr.print(
            f"note: one process drives {n_gpus} GPUs on warp at ~1.5x one GPU; "
            f"--processes {n_gpus} runs one process per GPU (~1.8-1.9x)"
        )
    built = Built(scene, options, build_s)
    if plan.want_video:
        built.camera = args.video_camera or default_camera(scene)
        camera_id(scene.mj_model, built.camera)
        try:
            built.gl = gl_backend()
        except GLUnavailable as e:
            built.no_gl = e
    return built


# ---- execute ---------------------------------------------------------------------------------


def execute(
    plan: EvalPlan, built: Built, owned: contextlib.ExitStack
) -> Evaluation | EvalReport | SweepReport:
    """Run the evaluation (a suite: every task in turn; a sweep: every point) under a progress
    bar; an `Evaluation` keeps its scene and arrays for what `write` re-simulates."""
    args = plan.args
    with Progress(
        TextColumn("{task.description}"),
        BarColumn(),
        MofNCompleteColumn(),
        TimeElapsedColumn(),
        console=stderr,
        transient=True,
        disable=not processes.is_primary(),
    ) as progress:
        bar = progress.add_task(f"compiling {args.scene} on {plan.backend}", total=None)

        def on_chunk(done: int, total: int, successes: int) -> None:
            # Over the first `done` seeds only: the runners report a finished prefix, never
            # whatever has finished (early successes would inflate it).
            rate = f" success {100 * successes / done:.1f}%" if done else ""
            progress.update(bar, description=f"episodes{rate}", completed=done, total=total)

        if args.suite is not None:
            return _execute_suite(plan, progress, bar)
        assert built.scene is not None
        if args.sweep is not None:
            return _execute_sweep(plan, built, progress, bar, on_chunk)
        evaluation = evaluate_spec(
            built.scene,
            args.policy,
            plan.spec,
            on_chunk=on_chunk,
            resume=plan.resume if isinstance(plan.resume, EvalReport) else None,
            decide=plan.decide,
            keep_finished=not writes_media(args),
            build_s=built.build_s,
        )
    owned.enter_context(evaluation)
    return evaluation


def _execute_suite(plan: EvalPlan, progress: Progress, bar: TaskID) -> EvalReport:
    """Every task of `--suite`, one after another or `--task-processes`/`--cluster` at once."""
    args = plan.args
    together = args.task_processes > 1 or args.cluster is not None

    def on_task(i: int, n: int, name: str) -> None:
        if together:  # called as each task ends, `i` of `n` done
            progress.update(bar, description=f"tasks done ({name})", completed=i, total=n)
        else:
            progress.update(bar, description=f"task {i + 1}/{n} {name}", completed=0, total=None)

    if together and plan.backend in ("mjx", "warp") and not mps_running():
        stderr.print(
            f"note: --task-processes {args.task_processes} without NVIDIA's MPS daemon: "
            "processes take turns on a GPU (start it: nvidia-cuda-mps-control -d)"
        )
    return evaluate_suite(
        args.scene,
        args.suite,
        args.policy,
        plan.spec,
        options=plan.options,
        task_processes=args.task_processes,
        compile_cache=default_cache_dir() if args.compile_cache else None,
        on_task=on_task,
        on_chunk=lambda done, total, _: progress.update(bar, completed=done, total=total),
        resume=plan.resume if isinstance(plan.resume, EvalReport) else None,
        cluster=args.cluster,
    )


def _execute_sweep(
    plan: EvalPlan,
    built: Built,
    progress: Progress,
    bar: TaskID,
    on_chunk: Callable[[int, int, int], None],
) -> SweepReport:
    """Every point of `--sweep`, here or over `--cluster`."""
    args = plan.args
    name = args.sweep.partition("=")[0]

    def on_point(i: int, n: int, value: float) -> None:
        if args.cluster is not None:  # called as each point ends, `i` of `n` done
            description = f"points done ({name}={value:g})"
            progress.update(bar, description=description, completed=i, total=n)
            return
        progress.update(bar, description=f"{name}={value:g} ({i + 1}/{n})", completed=0, total=None)

    cluster = None
    if args.cluster is not None:
        cluster = SweepCluster(args.cluster, args.scene, built.options, args.compile_cache)
    return run_sweep(
        built.scene,
        args.policy,
        args.sweep,
        # --plots draws the sweep's curve, not reward curves: no per-step rewards
        dataclasses.replace(plan.spec, step_rewards=False),
        randomize=parse_factors(args.randomize),
        on_point=on_point,
        on_chunk=on_chunk,
        resume=plan.resume if isinstance(plan.resume, SweepReport) else None,
        cluster=cluster,
    )


# ---- write -----------------------------------------------------------------------------------


@dataclasses.dataclass
class Written:
    """What `write` put on disk, for `show`: the report, the frames file, plots and videos (with
    the traces they show), notes for the user, and why videos could not be rendered."""

    report: EvalReport
    frames_file: Path | None = None
    plots: list[Path] = dataclasses.field(default_factory=list)
    videos: list[tuple[Path, EpisodeTrace]] = dataclasses.field(default_factory=list)
    notes: list[str] = dataclasses.field(default_factory=list)
    no_gl: GLUnavailable | None = None


def write(plan: EvalPlan, built: Built, result: Evaluation | EvalReport) -> Written | None:
    """Write the report (atomically), then frames, plots and videos beside it. Only process 0
    of a job writes (the others return None)."""
    args = plan.args
    evaluation = result if isinstance(result, Evaluation) else None
    report = result.report if isinstance(result, Evaluation) else result
    if not processes.is_primary():
        return None
    written = Written(report)
    if evaluation is not None and plan.frames_file is not None:  # the report names the frames
        with stderr.status(f"re-simulating {min(args.frames, report.n_episodes)} episode(s)"):
            arrays = record_frames(evaluation, args.frames, plan.frames_file.name)
        save_frames(plan.frames_file, arrays)
        written.frames_file = plan.frames_file
    save_report(report, plan.out)
    if evaluation is None:
        return written
    if args.plots:
        written.plots = write_plots(report, plan.stem, evaluation.arrays["rewards"])
    if plan.want_video:
        if built.no_gl is not None:
            written.no_gl = built.no_gl
        else:
            written.videos, notes = write_videos(evaluation, args, plan.videos_dir, built)
            written.notes += notes
    return written


def write_videos(
    evaluation: Evaluation, args: EvalArgs, folder: Path, built: Built
) -> tuple[list[tuple[Path, EpisodeTrace]], list[str]]:
    """Re-simulate the chosen episodes and write one MP4 each into `folder`; the videos with
    their traces, and notes (fewer failures to film than asked)."""
    seeds = choose_seeds(evaluation, args.video, args.video_failures)
    failed = int((~evaluation.arrays["success"]).sum())
    notes = []
    if failed < args.video_failures:
        notes.append(f"{failed} failed episode(s) to film, not {args.video_failures}")
    with stderr.status(f"re-simulating {len(seeds)} episode(s) for videos"):
        traces = trace_episodes(evaluation, seeds)
    videos = []
    for trace in traces:
        path = folder / f"seed{trace.seed}_{trace.outcome}.mp4"
        with stderr.status(f"rendering {path.name}"):
            write_episode_video(
                path, evaluation.scene, args.policy, trace, camera=built.camera, gl=built.gl
            )
        videos.append((path, trace))
    return videos, notes


# ---- show ------------------------------------------------------------------------------------


def show(plan: EvalPlan, written: Written) -> None:
    """Print the summary, the breakdown and comparison, and where each file went; a renderer
    that was missing for videos is raised last (exit code 2, after everything else is out)."""
    args, report = plan.args, written.report
    print(report.summary())
    if args.suite is not None:
        print(format_tasks(report))
    if report.cluster is not None:
        print(report.cluster.summary())
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
    if report.decision is not None:
        print(decision_summary(report, plan.baseline))
    elif plan.baseline is not None:
        rc = compare_reports(
            plan.baseline,
            report,
            mirrored=mirrored(plan.baseline.scene, report.scene),
            seed_options=seed_options(plan.baseline.scene, report.scene),
        )
        names = (str(args.compare_with), str(plan.out))
        print(format_comparison(rc, plan.baseline, report, names))
    if written.frames_file is not None:
        print(f"frames: {written.frames_file}")
    print(f"report: {plan.out}")
    for path in written.plots:
        print(f"plot: {path}")
    for note in written.notes:
        print(f"note: {note}")
    for path, trace in written.videos:
        differs = "" if trace.reproduced else "; re-simulation DIFFERS from the evaluated episode"
        print(f"video: {path} ({trace.outcome} at step {trace.steps}{differs})")
    if written.no_gl is not None:
        raise GLUnavailable(f"cannot render videos: {written.no_gl}")


def write_sweep(plan: EvalPlan, report: SweepReport) -> list[Path]:
    """Write the sweep report (atomically) and, with --plots, its curve; the plots written."""
    save_sweep(report, plan.out)
    if not plan.args.plots:
        return []
    return [save_png(sweep_curve(report), plan.stem.with_name(f"{plan.stem.name}_sweep.png"))]


def show_sweep(plan: EvalPlan, report: SweepReport, plots: list[Path]) -> None:
    print(report.summary())
    if report.cluster is not None:
        print(report.cluster.summary())
    print(f"report: {plan.out}")
    for path in plots:
        print(f"plot: {path}")


# ---- the command -----------------------------------------------------------------------------


def run(args: EvalArgs) -> int:
    """validate -> build -> execute -> write -> show; with `--processes N`, validate here and
    launch N processes that each run the pipeline; with `--distributed auto`, join the job a
    cluster's launcher started, then run it."""
    if args.list:
        print(listing())
        return 0
    launcher = args.processes != 1 and processes.rank() is None
    if args.distributed is not None:
        check_distributed(args)  # before joining: a refused process would leave peers waiting
    if not launcher:
        processes.initialize(args.distributed)  # before anything touches a device
    plan = validate(args)
    if launcher:
        with signals_raise():  # SIGTERM too ends the job's processes (launch stops them)
            return processes.launch("openral_mjx.eval", sys.argv[1:], args.processes)
    # SIGTERM stops a run as Ctrl-C does; MuJoCo's warnings are counted, not printed or logged
    with signals_raise(), count_warnings() as warned:
        try:
            with contextlib.ExitStack() as owned:  # worker processes, policy servers
                built = build(plan, owned)
                result = execute(plan, built, owned)
                if isinstance(result, SweepReport):
                    show_sweep(plan, result, write_sweep(plan, result))
                else:
                    written = write(plan, built, result)
                    if written is not None:
                        show(plan, written)
        except Interrupted as stop:
            return keep_partial(plan, stop)
        except RunFailed as failed:
            return keep_failed(plan, failed)
        finally:
            if warned:
                print(warnings_line(warned), file=sys.stderr)
    processes.finish()
    return 0


def keep_failed(plan: EvalPlan, failed: RunFailed) -> int:
    """A run that failed after some of it finished (`RunFailed` with a partial report): write
    that to --out and say, on one line, why it stopped, what it kept and how to finish it;
    exit code 1. Without a report, the error's line alone."""
    report = failed.report
    if isinstance(report, EvalReport) and report.partial is not None and processes.is_primary():
        save_report(report, plan.out)
        print(
            f"error: {failed}; kept {report.partial.describe()} in {plan.out}; "
            f"finish with: {plan.command} --resume",
            file=sys.stderr,
        )
    else:
        print(f"error: {failed}", file=sys.stderr)
    return 1


def keep_partial(plan: EvalPlan, stop: Interrupted) -> int:
    """Write an interrupted run's partial report to --out and say, on one line, what it
    kept and how to finish it; the exit code of the signal (130 SIGINT, 143 SIGTERM)."""
    report = stop.report
    assert report.partial is not None
    if processes.is_primary():
        if isinstance(report, SweepReport):
            save_sweep(report, plan.out)
        else:
            save_report(report, plan.out)
        print(
            f"{report.partial.reason}: kept {report.partial.describe()} in {plan.out}; "
            f"finish with: {plan.command} --resume",
            file=sys.stderr,
        )
    return EXIT_CODES[stop.signal]


def main(argv: Sequence[str] | None = None) -> None:
    """The command: `argv` (default: the process's arguments) -> exit code."""
    prog = "python -m openral_mjx.eval"
    args = parse(lambda: tyro.cli(EvalArgs, prog=prog, args=argv), prog)
    raise SystemExit(guarded(lambda: run(args)))


if __name__ == "__main__":
    main()
