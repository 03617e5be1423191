"""`python -m openral_mjx.eval`: success rate with a confidence interval, throughput, a report.

Example: ``python -m openral_mjx.eval --scene tabletop_push --n-envs 1024``.

The command is a pipeline of named steps, each a function of what the step before returned:
`validate` (every flag and option, the report path, before anything is built) -> `build` (the
scene, the video renderer) -> `execute` (the evaluation, with a progress bar) -> `write`
(report, frames, plots, videos) -> `show` (the summary and where each file went). The work
itself is the library's (`openral_mjx.evaluation`); this module parses, checks and prints.
"""

from __future__ import annotations

import contextlib
import dataclasses
import datetime as dt
import re
import sys
from collections.abc import Sequence
from pathlib import Path
from typing import Annotated, Literal

import tyro
from rich.progress import BarColumn, MofNCompleteColumn, Progress, TextColumn, TimeElapsedColumn

from openral_mjx.cli.common import command_line, guarded, parse, stderr
from openral_mjx.core.errors import ConfigError
from openral_mjx.core.files import check_writable
from openral_mjx.core.interrupts import EXIT_CODES, signals_raise
from openral_mjx.core.options import load_yaml, parse_overrides
from openral_mjx.evaluation import Evaluation, RunSpec, cluster
from openral_mjx.evaluation.frames import check_frames, record_frames, save_frames
from openral_mjx.evaluation.partial import Interrupted
from openral_mjx.evaluation.replay import EpisodeTrace, choose_seeds, trace_episodes
from openral_mjx.evaluation.run import build_spec_scene, evaluate_spec, policy_options
from openral_mjx.evaluation.sequential import PairedRule, paired_rule
from openral_mjx.evaluation.suite import evaluate_suite, format_tasks, mps_running
from openral_mjx.evaluation.sweep import SweepCluster, parse_sweep, run_sweep
from openral_mjx.physics import BACKEND_NAMES
from openral_mjx.physics.gl import GLUnavailable, camera_id, gl_backend
from openral_mjx.physics.mj_warnings import count_warnings, format_warnings
from openral_mjx.policies import POLICIES
from openral_mjx.report import EvalReport, load_report, save_report
from openral_mjx.report.sweep import SweepReport, load_sweep, save_sweep
from openral_mjx.robots import ROBOTS
from openral_mjx.runner import processes
from openral_mjx.runner.compile_cache import default_cache_dir, enable_compilation_cache
from openral_mjx.scenes import (
    SCENES,
    Scene,
    check_robot,
    check_task,
    mirrored,
    resolve_scene_backend,
    scene_options,
    scene_suite,
    scripted_policy,
)
from openral_mjx.scenes.factor_ranges import parse_factors
from openral_mjx.scenes.host_scene import HostScene
from openral_mjx.stats import compare_reports, format_breakdown, format_comparison
from openral_mjx.viz import require_viz
from openral_mjx.viz.plots import save_png, sweep_curve, write_plots
from openral_mjx.viz.video import default_camera, write_episode_video


def _per_scene(what: str) -> str:
    """Each scene's task naming (`what="tasks"`) or suite names (`"suites"`), ``scenes: text``
    joined by semicolons (scenes with the same text, a mirror and its original, together), for
    the --task/--suite help: read from `SCENES`, so a scene's registration is its help too."""
    by_text: dict[str, list[str]] = {}
    for name in SCENES.names():
        entry = SCENES.get(name)
        text = entry.tasks if what == "tasks" else ", ".join(entry.suite_names)
        if text:
            by_text.setdefault(text, []).append(name)
    return "; ".join(f"{', '.join(names)}: {text}" for text, names in by_text.items())


TASK_HELP = f"Task of a multi-task scene (--list shows each scene's): {_per_scene('tasks')}."
SUITE_HELP = (
    f"Evaluate every task of a suite ({_per_scene('suites')}); reports per-task rates and "
    "their average."
)


@dataclasses.dataclass
class EvalArgs:
    """Evaluate a policy on a MuJoCo scene over many seeds at once."""

    scene: str = "tabletop_push"
    """Scene ID (see --list)."""
    policy: str = "scripted"
    """Policy ID, or ID:ARG (see --list)."""
    task: Annotated[str | None, tyro.conf.arg(help=TASK_HELP)] = None
    suite: Annotated[str | None, tyro.conf.arg(help=SUITE_HELP)] = None
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
    batching: str = "auto"
    """refill: continuous batching, a slot whose episode ended takes the next seed (mjx, warp
    and c); chunks: fixed batches of n_envs seeds, each run for max_steps; auto: refill when
    there are more episodes than envs and it applies (not host scenes, not --plots). Per
    seed the episodes are the same. With --suite, every task runs so."""
    refill_every: int = 1
    """--batching refill: reset ended slots every this many control steps (batched resets)."""
    seed: int = 0
    """First seed; episodes use seeds seed .. seed+n_episodes-1."""
    config: Path | None = None
    """YAML file of scene options (see configs/)."""
    opt: tuple[str, ...] = ()
    """Scene option overrides, KEY=VALUE (after --config)."""
    randomize: tuple[str, ...] = ()
    """Factors drawn per seed, NAME=LOW:HIGH (LOWx:HIGHx: multiples of the model's values) or
    NAME=VALUE: friction, mass, kp, damping, armature (physics), delay, action_noise
    (control), joint_noise, object_noise, depth_noise, depth_dropout, camera_pos, camera_rot,
    light (sensing; light: RGB images on warp). Each is an episode factor in the report's
    breakdown."""
    sweep: str | None = None
    """NAME=LOW:HIGH:N: run the same seeds at N evenly spaced values of one factor; writes a
    sweep report (success per value, paired tests between neighbours, Holm-corrected)."""
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
    not (see docs/gpu.md)."""
    distributed: Literal["auto"] | None = None
    """auto: this process is one of a job that a cluster's launcher started (srun, mpirun; one
    process per GPU), joined through JAX's detection of the launcher's environment; the seeds
    shard over every process's devices and process 0 alone prints and writes (docs/backends.md)."""
    task_processes: int = 1
    """With --suite: run this many tasks at once, one process each. On one GPU it pays only
    under NVIDIA's MPS daemon (nvidia-cuda-mps-control -d): 16 MetaWorld tasks at 1,000 envs
    ran 3.6x faster together than one at a time with MPS, 0.94x without (8 tasks)."""
    cluster: str | None = None
    """With --suite (or --sweep): run its tasks (points) as Ray tasks on the cluster at this
    address (auto: the one `ray start` runs here; local: one started for this run; HOST:PORT or
    ray://HOST:PORT), each on a GPU where the cluster has GPUs and the backend uses them, else
    on --threads CPUs (default 1). Per seed the same episodes as a local run; the report says
    where each task (point) ran. For a host scene without --suite: its env workers run as Ray
    actors on the cluster's nodes (one CPU each, one per cluster CPU by default). Needs the ray
    extra (docs/cluster.md)."""
    out: Path | None = None
    """Report path (default: results/SCENE_POLICY_TIMESTAMP.json)."""
    factor_bins: int = 5
    """Equal-count bins per episode factor in the report's success breakdown (not with --suite:
    a suite report has no breakdown)."""
    breakdown: bool = True
    """Print the success breakdown by episode factor."""
    compare_with: Path | None = None
    """A report of the same scene to compare this run with (paired by seed where shared)."""
    decide: bool = False
    """With --compare-with A.json: run this policy (B) on A's seeds in looks of --n-envs and
    stop at the first look where B is better or worse than A, or within +-margin of it
    (a group-sequential test with exact error rates); --n-episodes caps it (default: every
    seed A's report has from --seed)."""
    margin: float | None = None
    """--decide: call B equivalent to A once the interval for B - A lies inside +-this (0.05:
    five points); without it --decide only stops for a difference."""
    alpha: float = 0.05
    """--decide: error rate; the test of no difference spends 0.9 alpha, and the interval for
    B - A covers with probability >= 1 - alpha under the stopping rule."""
    spending: str = "obrien-fleming"
    """--decide: how alpha is spent over the looks: obrien-fleming (little early, a cap close
    to a fixed-size test's) or pocock (more early)."""
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
    resume: bool = False
    """Finish the --sweep, --suite, --target-halfwidth or --decide run whose partial report
    (written at Ctrl-C or SIGTERM) is at --out: give the interrupted run's arguments; its
    finished points, tasks or chunks of seeds are kept, the rest run."""
    list: bool = False
    """List scenes, policies, robots and backends, then exit."""


# ---- validate --------------------------------------------------------------------------------

# The most episodes re-simulated for videos or sensor frames (each is a file, or a slice of
# one, held in memory while it is written).
MAX_VIDEOS = 1000


@dataclasses.dataclass(frozen=True)
class EvalPlan:
    """An `eval` invocation checked in full: what to run and where every file goes.

    Nothing has been built or run to get it; `validate` is the only step that can reject the
    user's input without having spent time first (`build` still checks what needs the compiled
    model: the video camera and the scene's sensors for `--frames`).
    """

    args: EvalArgs
    backend: str
    options: dict
    out: Path
    baseline: EvalReport | None
    spec: RunSpec
    resume: EvalReport | SweepReport | None = None
    decide: PairedRule | None = None

    @property
    def command(self) -> str:
        """The command line that reproduces this run (the report's `command`)."""
        return self.spec.command

    @property
    def want_video(self) -> bool:
        return self.args.video > 0 or self.args.video_failures > 0

    @property
    def stem(self) -> Path:
        """The report path without `.json`: plots and videos are named after it."""
        return self.out.with_suffix("")

    @property
    def frames_file(self) -> Path | None:
        return self.out.with_name(f"{self.stem.name}.frames.npz") if self.args.frames else None

    @property
    def videos_dir(self) -> Path:
        return self.stem.with_name(f"{self.stem.name}_videos")


def validate(args: EvalArgs) -> EvalPlan:
    """Check every flag, option and path, and load `--compare-with`; raise `ConfigError` naming
    the first bad value. Touches no device where the backend is named (a `--processes`
    launcher must not take the GPUs its processes will use)."""
    SCENES.get(args.scene)
    POLICIES.get(args.policy.partition(":")[0])
    if args.processes != 1:
        _check_processes(args)
    if args.distributed is not None:
        _check_distributed(args)
    backend = resolve_scene_backend(args.scene, args.backend)
    options = _scene_options(args)
    spec = _run_spec(args, backend)
    if min(args.video, args.video_failures) < 0:
        raise ConfigError(
            f"--video and --video-failures must be >= 0, got {args.video}, {args.video_failures}"
        )
    if args.frames < 0:
        raise ConfigError(f"frames must be >= 0, got {args.frames}")
    for flag, count in (("--video", args.video), ("--video-failures", args.video_failures)):
        if count > MAX_VIDEOS:
            raise ConfigError(f"{flag} must be at most {MAX_VIDEOS}, got {count}")
    if args.frames > MAX_VIDEOS:
        raise ConfigError(f"--frames must be at most {MAX_VIDEOS}, got {args.frames}")
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
        spec.for_suite()
    elif args.task_processes != 1:
        raise ConfigError("--task-processes runs the tasks of a --suite at once: give --suite")
    if args.cluster is not None:
        _check_cluster(args, backend)
    _check_randomize(args, want_video)
    policy = scripted_policy(args.scene, args.policy)
    if policy != args.policy:
        note = f"note: scene {args.scene!r} has no scripted policy of its own: running {policy}"
        print(note, file=sys.stderr)
        args = dataclasses.replace(args, policy=policy)
    out = args.out or _default_out(args)
    check_writable(out)
    baseline = None
    if args.compare_with is not None:
        baseline = load_report(args.compare_with)
        if baseline.scene != args.scene and not mirrored(baseline.scene, args.scene):
            raise ConfigError(
                f"reports are not comparable: scene {baseline.scene!r} ({args.compare_with}) "
                f"vs {args.scene!r}"
            )
    decide = _decide_rule(args, baseline)
    if decide is not None:
        spec = dataclasses.replace(spec, n_episodes=decide.cap)
    spec = dataclasses.replace(spec, command=_reproduce(args, backend, out))
    resume = _resume_from(args, spec.command) if args.resume else None
    return EvalPlan(args, backend, options, out, baseline, spec, resume, decide)


def _decide_rule(args: EvalArgs, baseline: EvalReport | None) -> PairedRule | None:
    """`--decide`'s stopping rule against `--compare-with`'s report, checked (None without
    --decide; its design flags without it are refused, not ignored)."""
    design_flags = [
        flag
        for flag, on in (
            ("--margin", args.margin is not None),
            ("--alpha", args.alpha != 0.05),
            ("--spending", args.spending != "obrien-fleming"),
        )
        if on
    ]
    if not args.decide:
        if design_flags:
            flags = ", ".join(design_flags)
            raise ConfigError(f"{flags} set the design of --decide: give --decide")
        return None
    if baseline is None or args.compare_with is None:
        raise ConfigError(
            "--decide runs this policy until it is decided against an earlier report: give "
            "--compare-with A.json"
        )
    extras = [
        flag
        for flag, on in (
            ("--target-halfwidth", args.target_halfwidth is not None),
            ("--max-episodes", args.max_episodes is not None),
            ("--suite", args.suite is not None),
            ("--sweep", args.sweep is not None),
            ("--processes", args.processes != 1),
            ("--distributed", args.distributed is not None),
        )
        if on
    ]
    if extras:
        raise ConfigError(
            f"--decide chooses its own stop (cap: --n-episodes): drop {', '.join(extras)}"
        )
    if args.task is not None and baseline.task != args.task:
        raise ConfigError(
            f"reports are not comparable: task {baseline.task!r} ({args.compare_with}) vs "
            f"{args.task!r}"
        )
    return paired_rule(
        baseline,
        str(args.compare_with),
        args.seed,
        args.n_episodes,
        args.alpha,
        args.margin,
        args.spending,
    )


def _resume_from(args: EvalArgs, command: str) -> EvalReport | SweepReport:
    """The partial report at --out that --resume picks up, checked to be one this very
    command wrote (same arguments, so the same seeds, options and grid)."""
    resumable = (args.sweep, args.suite, args.target_halfwidth, args.decide or None)
    if all(x is None for x in resumable):
        raise ConfigError(
            "--resume finishes an interrupted --sweep, --suite, --target-halfwidth or --decide "
            "run: give its arguments"
        )
    if args.video or args.video_failures or args.frames or args.plots:
        raise ConfigError("--resume writes the report only: drop --video/--frames/--plots")
    if args.out is None:
        raise ConfigError("--resume needs --out: the partial report to pick up from")
    report = load_sweep(args.out) if args.sweep is not None else load_report(args.out)
    if report.partial is None:
        raise ConfigError(f"--resume: report {str(args.out)!r} is complete; nothing to resume")
    if report.command != command:
        raise ConfigError(
            f"--resume: report {str(args.out)!r} was written by another command "
            f"({report.command}); give its arguments"
        )
    return report


def _run_spec(args: EvalArgs, backend: str) -> RunSpec:
    """The run's settings from the flags, checked (`ConfigError` naming the first bad one)."""
    return RunSpec(
        n_envs=args.n_envs,
        n_episodes=args.n_episodes,
        target_halfwidth=args.target_halfwidth,
        max_episodes=args.max_episodes,
        max_steps=args.max_steps,
        seed=args.seed,
        factor_bins=args.factor_bins,
        batching=args.batching,
        refill_every=args.refill_every,
        step_rewards=args.plots,
        backend=backend,
        threads=args.threads,
        contacts_per_env=args.contacts_per_env,
        devices=args.devices,
    )


def _default_out(args: EvalArgs) -> Path:
    stamp = dt.datetime.now().strftime("%Y%m%d-%H%M%S")
    policy_tag = re.sub(r"[^A-Za-z0-9_.-]+", "-", args.policy).strip("-")  # mlp:a/b: mlp-a-b
    kind = "" if args.sweep is None else f"_sweep-{args.sweep.partition('=')[0]}"
    return Path("results") / f"{args.scene}_{policy_tag}{kind}_{stamp}.json"


def _check_randomize(args: EvalArgs, want_video: bool) -> None:
    """`--randomize` and `--sweep` parse, and combine only with what they support."""
    if not args.randomize and args.sweep is None:
        return
    ranges = parse_factors(args.randomize)
    if SCENES.get(args.scene).backends is not None:
        raise ConfigError(
            f"scene {args.scene!r} runs in host workers: --randomize/--sweep need a MuJoCo "
            "scene (mjx, warp or c)"
        )
    if args.suite is not None:
        raise ConfigError("--randomize/--sweep take one task: drop --suite")
    if args.sweep is None:
        return
    parse_sweep(args.sweep, ranges)
    extras = [
        flag
        for flag, on in (
            ("--target-halfwidth", args.target_halfwidth is not None),
            ("--video", want_video),
            ("--frames", args.frames > 0),
            ("--compare-with", args.compare_with is not None),
            ("--processes", args.processes != 1),
            ("--distributed", args.distributed is not None),
        )
        if on
    ]
    if extras:
        raise ConfigError(f"--sweep runs one report over its grid: drop {', '.join(extras)}")


def _scene_options(args: EvalArgs) -> dict:
    """The scene's option overrides from --config, --opt, --task and the robot flags, checked
    against the scene's options class."""
    check_robot(args.scene, args.robot, args.robot_mjcf)
    options: dict = {}
    if args.config is not None:
        options.update(load_yaml(args.config))
    options.update(parse_overrides(args.opt))
    if check_task(args.scene, args.task):
        options["task"] = args.task
    if args.robot is not None:
        ROBOTS.get(args.robot)
        options["robot"] = args.robot
    if args.robot_mjcf is not None:
        if not args.robot_mjcf.is_file():
            raise ConfigError(f"robot MJCF {str(args.robot_mjcf)!r} does not exist")
        options["robot_mjcf"] = str(args.robot_mjcf)
    scene_options(args.scene, options)
    return options


def _check_processes(args: EvalArgs, job: str | None = None) -> None:
    """What a job of several processes cannot do, refused before any starts (`job`: the flag
    that asked for one, default --processes N)."""
    if job is None:
        processes.check_count(args.processes)
        job = f"--processes {args.processes}"
    if args.backend not in ("mjx", "warp"):
        raise ConfigError(
            f"{job} shards envs over GPUs: give --backend mjx or warp, not {args.backend!r}"
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
        raise ConfigError(f"{job} does not combine with {', '.join(extras)}")


def _check_distributed(args: EvalArgs) -> None:
    """`--distributed auto` joins a job a cluster's launcher started: not with --processes (the
    launcher starts the processes), what --processes refuses, and only in a launcher's
    environment (refused here, before JAX waits for peers that will never come)."""
    if args.processes != 1:
        raise ConfigError(
            "--distributed auto joins the processes a cluster's launcher started: drop --processes"
        )
    _check_processes(args, "--distributed auto")
    processes.check_launcher()


def _check_suite(args: EvalArgs, want_video: bool) -> None:
    """`--suite` runs every task of the suite with a fixed episode count and no videos, plots
    or frames."""
    if args.task is not None or args.target_halfwidth is not None:
        raise ConfigError("--suite runs every task of the suite: drop --task/--target-halfwidth")
    processes.check_count(args.task_processes, "--task-processes")
    if want_video or args.plots or args.frames:
        raise ConfigError("--suite writes one report over its tasks: drop --video/--plots/--frames")
    scene_suite(args.scene, args.suite)


def _check_cluster(args: EvalArgs, backend: str) -> None:
    """`--cluster` fans a suite's tasks, a sweep's points, or a host scene's env workers out
    over Ray: it needs one of them and Ray, a valid address, and no local fan-out beside it."""
    if args.suite is None and args.sweep is None and backend != "host":
        raise ConfigError(
            "--cluster runs the tasks of a --suite, the points of a --sweep, or a host scene's "
            f"env workers on Ray workers: give --suite or --sweep (scene {args.scene!r} runs on "
            f"{backend})"
        )
    if args.task_processes != 1 or args.processes != 1:
        raise ConfigError(
            "--cluster runs a suite's tasks on Ray workers: drop --task-processes/--processes"
        )
    cluster.check_address(args.cluster)
    cluster.require_ray()


def _reproduce(args: EvalArgs, backend: str, out: Path) -> str:
    """The command line that reproduces this run (the report's `command`)."""
    argv = ["--scene", args.scene, "--policy", args.policy, "--backend", backend]
    argv += ["--n-envs", str(args.n_envs), "--seed", str(args.seed), "--out", str(out)]
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
        ("--distributed", args.distributed),
        ("--task-processes", args.task_processes if args.task_processes != 1 else None),
        ("--cluster", args.cluster),
        ("--factor-bins", args.factor_bins if args.factor_bins != 5 else None),
        ("--frames", args.frames or None),
        ("--batching", args.batching if args.batching != "auto" else None),
        ("--refill-every", args.refill_every if args.refill_every != 1 else None),
    ):
        if value is not None:
            argv += [flag, str(value)]
    if args.sweep is not None:
        argv += ["--sweep", args.sweep]
    if args.decide:
        argv += ["--compare-with", str(args.compare_with), "--decide"]
        argv += ["--alpha", str(args.alpha), "--spending", args.spending]
        argv += [] if args.margin is None else ["--margin", str(args.margin)]
    if args.randomize:
        argv += ["--randomize", *args.randomize]
    if args.opt:
        argv += ["--opt", *args.opt]
    return command_line("openral_mjx.eval", argv)


# ---- build -----------------------------------------------------------------------------------


@dataclasses.dataclass
class Built:
    """What `build` made for the run: the scene (None for a suite, which builds one per task)
    with the options it was built from and, for videos, the camera and the GL backend (or why
    there is none: the run still goes ahead and writes its report, and the missing renderer is
    reported at the end)."""

    scene: Scene | None = None
    options: dict = dataclasses.field(default_factory=dict)
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
    built = Built(scene, options)
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
    """Run the evaluation (a suite: every task in turn) under a progress bar; an `Evaluation`
    keeps its scene and arrays for what `write` re-simulates."""
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
            together = args.task_processes > 1 or args.cluster is not None

            def on_task(i: int, n: int, name: str) -> None:
                if together:  # called as each task ends, `i` of `n` done
                    progress.update(bar, description=f"tasks done ({name})", completed=i, total=n)
                else:
                    progress.update(
                        bar, description=f"task {i + 1}/{n} {name}", completed=0, total=None
                    )

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
        assert built.scene is not None
        if args.sweep is not None:

            def on_point(i: int, n: int, value: float) -> None:
                name = args.sweep.partition("=")[0]
                if args.cluster is not None:  # called as each point ends, `i` of `n` done
                    description = f"points done ({name}={value:g})"
                    progress.update(bar, description=description, completed=i, total=n)
                    return
                progress.update(
                    bar, description=f"{name}={value:g} ({i + 1}/{n})", completed=0, total=None
                )

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
                cluster=None
                if args.cluster is None
                else SweepCluster(args.cluster, args.scene, built.options, args.compile_cache),
            )
        evaluation = evaluate_spec(
            built.scene,
            args.policy,
            plan.spec,
            on_chunk=on_chunk,
            resume=plan.resume if isinstance(plan.resume, EvalReport) else None,
            decide=plan.decide,
        )
    owned.enter_context(evaluation)
    return evaluation


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
            plan.baseline, report, mirrored=mirrored(plan.baseline.scene, report.scene)
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


DECIDED = {
    "better": "B's success rate is higher than A's",
    "worse": "B's success rate is lower than A's",
    "equivalent": "B's success rate is within +-{margin} points of A's",
    "inconclusive": "no decision by the cap",
}


def decision_summary(report: EvalReport, baseline: EvalReport | None) -> str:
    """The lines of `--decide`: the verdict, the looks and the interval valid under the rule."""
    d = report.decision
    assert d is not None
    margin = "" if d.margin is None else f"{100 * d.margin:g}"
    verdict = DECIDED[d.decision].format(margin=margin)
    a = f"A: {d.baseline} ({d.baseline_policy})" + (
        f", {baseline.success_rate:.1%} over its {baseline.n_episodes:,} seeds"
        if baseline is not None
        else ""
    )
    lines = [
        a,
        f"decide: {verdict}; stopped at look {len(d.looks)} of {-(-d.cap // d.chunk)}, "
        f"{report.n_episodes:,} of at most {d.cap:,} seeds",
        "  look  seeds  only A  only B  stop if only B <=  or >=",
    ]
    for i, look in enumerate(d.looks, 1):
        lines.append(
            f"  {i:>4}  {look.n:>5,}  {look.only_a:>6}  {look.only_b:>6}  {look.lower:>16}  "
            f"{look.upper:>5}"
        )
    level = f"{100 * (1 - d.alpha):g}%"
    lines.append(
        f"B - A = {100 * d.difference:+.1f} points, {level} repeated CI [{100 * d.ci_low:+.1f}, "
        f"{100 * d.ci_high:+.1f}] (valid under the stopping rule)"
    )
    lines.append(f"design: {d.rule}")
    return "\n".join(lines)


def _scene_listing(name: str) -> list[str]:
    """Scene `name`'s lines in --list, from its registration: backends, robot, tasks, suites."""
    entry = SCENES.get(name)
    backends = entry.backends or tuple(b for b in BACKEND_NAMES if b != "auto")
    robot_field = {f.name: f for f in dataclasses.fields(entry.options_cls)}.get("robot")
    if entry.fixed_robot is not None:
        robot = entry.fixed_robot
    elif robot_field is not None:
        robot = f"--robot or --robot-mjcf (default {robot_field.default})"
    else:
        robot = "none"
    lines = [f"  {name}: backends {', '.join(backends)}; robot {robot}"]
    if entry.tasks:
        lines.append(f"    --task  {entry.tasks}")
    if entry.suite_names:
        lines.append(f"    --suite {', '.join(entry.suite_names)}")
    return lines


def _listing() -> str:
    return "\n".join(
        [
            f"scenes:   {', '.join(SCENES.names())}",
            f"policies: {', '.join(POLICIES.names())}",
            f"robots:   {', '.join(ROBOTS.names())}",
            f"backends: {', '.join(BACKEND_NAMES)} (MuJoCo scenes), host (host scenes)",
            "",
            "scenes, as registered (tasks: --task; suites: --suite):",
            *(line for name in SCENES.names() for line in _scene_listing(name)),
        ]
    )


# ---- the command -----------------------------------------------------------------------------


def run(args: EvalArgs) -> int:
    """validate -> build -> execute -> write -> show; with `--processes N`, validate here and
    launch N processes that each run the pipeline; with `--distributed auto`, join the job a
    cluster's launcher started, then run it."""
    if args.list:
        print(_listing())
        return 0
    launcher = args.processes != 1 and processes.rank() is None
    if args.distributed is not None:
        _check_distributed(args)  # before joining: a refused process would leave peers waiting
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
        finally:
            if warned:
                print(warnings_line(warned), file=sys.stderr)
    processes.finish()
    return 0


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


def warnings_line(counts: dict[str, int]) -> str:
    """The one line that stands for MuJoCo's warnings (counted during the run, not shown)."""
    return (
        f"mujoco warnings: {format_warnings(counts)} (counted, not printed; by kind in the "
        "report's mujoco_warnings)"
    )


def main(argv: Sequence[str] | None = None) -> None:
    """The command: `argv` (default: the process's arguments) -> exit code."""
    prog = "python -m openral_mjx.eval"
    args = parse(lambda: tyro.cli(EvalArgs, prog=prog, args=argv), prog)
    raise SystemExit(guarded(lambda: run(args)))


if __name__ == "__main__":
    main()
