"""`eval`'s first step: every flag, option and path checked before anything is built.

`validate` turns `EvalArgs` into an `EvalPlan` (what to run, where every file goes, the
command that reproduces it) or raises a one-line `ConfigError` naming the first bad value.
"""

from __future__ import annotations

import dataclasses
import datetime as dt
import re
import sys
from pathlib import Path

from openral_mjx.cli.common import command_line, given_flags
from openral_mjx.cli.eval_args import EvalArgs
from openral_mjx.core.errors import ConfigError
from openral_mjx.core.files import check_writable
from openral_mjx.core.options import load_yaml, parse_overrides
from openral_mjx.evaluation import RunSpec, cluster
from openral_mjx.evaluation.sequential import PairedRule, paired_rule
from openral_mjx.evaluation.sweep import parse_sweep
from openral_mjx.policies import POLICIES
from openral_mjx.report import EvalReport, load_report
from openral_mjx.report.sweep import SweepReport, load_sweep
from openral_mjx.robots import ROBOTS
from openral_mjx.runner import processes
from openral_mjx.scenes import (
    SCENES,
    check_robot,
    check_task,
    mirrored,
    resolve_scene_backend,
    scene_options,
    scene_suite,
    scripted_policy,
    seed_options,
)
from openral_mjx.scenes.factor_ranges import parse_factors
from openral_mjx.stats.report_comparison import check_seed_options
from openral_mjx.viz import require_viz

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
        check_distributed(args)
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
        same = seed_options(baseline.scene, args.scene)
        check_seed_options(baseline.options, options, same, (str(args.compare_with), "this run"))
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


def writes_media(args: EvalArgs) -> bool:
    """Whether the run writes videos, frames or plots besides its report: interrupted, such a
    run keeps nothing, since `--resume` writes the report only."""
    return bool(args.video or args.video_failures or args.frames or args.plots)


def _resume_from(args: EvalArgs, command: str) -> EvalReport | SweepReport:
    """The partial report at --out that --resume picks up, checked to be one this very
    command wrote (same arguments, so the same seeds, options and grid)."""
    if writes_media(args):
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
        ccd_contacts_per_env=args.ccd_contacts_per_env,
        warp_graphs=args.warp_graphs,
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


def check_distributed(args: EvalArgs) -> None:
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
    argv += given_flags(
        (
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
            ("--ccd-contacts-per-env", args.ccd_contacts_per_env),
            ("--warp-graphs", args.warp_graphs),
            ("--devices", args.devices),
            ("--processes", args.processes if args.processes != 1 else None),
            ("--distributed", args.distributed),
            ("--task-processes", args.task_processes if args.task_processes != 1 else None),
            ("--cluster", args.cluster),
            ("--factor-bins", args.factor_bins if args.factor_bins != 5 else None),
            ("--frames", args.frames or None),
            ("--batching", args.batching if args.batching != "auto" else None),
            ("--refill-every", args.refill_every if args.refill_every != 1 else None),
        )
    )
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
