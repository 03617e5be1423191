"""`eval`'s flags: one tyro dataclass, its help read from the scene registrations."""

from __future__ import annotations

import dataclasses
from pathlib import Path
from typing import Annotated, Literal

import tyro

from openral_mjx.scenes import SCENES


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
    f"Evaluate every task of a suite ({_per_scene('suites')}), or of several comma-separated "
    "(e.g. libero_spatial,libero_object,libero_goal,libero_10); reports per-task rates and "
    "their average (and each suite's)."
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
    """Contact buffer per env of the warp backend (default 32, or the scene's); overflowing
    envs count as diverged."""
    ccd_contacts_per_env: int | None = None
    """Of those, how many may come from convex collision (GJK/EPA: meshes, cylinders), whose
    working buffers are the largest per contact (default: all); lower it to fit bigger
    batches of mesh-heavy scenes (LIBERO at 16,384 envs: 32-128)."""
    warp_graphs: Literal["warp", "staged", "none"] | None = None
    """How warp replays its calls as CUDA graphs (default: MJX's, warp): staged captures one
    graph per call site instead of one per buffer set, each with its own copy of the call's
    temporaries (use it when Warp cannot allocate at large batches); none uses no graphs."""
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
