"""Episode results and evaluation reports: dataclasses, JSON (de)serialisation, versioned.

Field names follow the predecessor's `EpisodeResult` (success, steps, total_reward, latency
fields, frames, metadata). `EvalReport` aggregates a run; `SCHEMA_VERSION` changes whenever a
field's meaning or presence changes. Reports of `READABLE_VERSIONS` load (keeping their own
version); any other version is an error.
"""

from __future__ import annotations

import dataclasses
from typing import Any

from openral_mjx.core.errors import ConfigError

SCHEMA_VERSION = "openral_mjx.eval_report/6"
# /2 has the same fields as /3; /3 only widened what the latency fields and metadata may hold
# (a torch policy's own latencies, a host worker's error), so a /2 report reads as it was.
# /4 added `live_env_steps_per_s` (continuous batching), None when read from /2 or /3.
# /5 added `instruction` (the report's and each per-task row's), None when read from /2../4.
# /6 added `partial` (an interrupted run's report of what finished; None: complete) and
# `mujoco_warnings` (MuJoCo's warnings by kind), None and {} when read from /2../5.
READABLE_VERSIONS = (
    "openral_mjx.eval_report/2",
    "openral_mjx.eval_report/3",
    "openral_mjx.eval_report/4",
    "openral_mjx.eval_report/5",
    SCHEMA_VERSION,
)


@dataclasses.dataclass
class EpisodeResult:
    """Outcome of one episode (one seed).

    Latencies: for a policy that measures its own per-step latency (a torch policy behind a
    host callback), its latency at each of this episode's steps: mean and max over them, and
    `budget_violations` the steps over `latency_budget_ms` (the scene's control period).
    Otherwise per control step of the whole batch (the batch advances in lock-step under
    one `jit`), measured per chunk: `mean_step_latency_ms` = chunk wall time / scanned steps,
    and `max_step_latency_ms` the largest such chunk mean over the run (per-step timing inside
    a fused scan is not observable); `budget_violations` counts this episode's steps taken
    while the batch step was slower than the control period.
    `metadata` carries seed, scene, task, robot, policy, backend, diverged, first_success_step,
    `factors` (the scene's randomised factors of this episode, name -> value) and, for host
    scenes, `error` (why a worker fault ended the episode, or null).
    `frames` is None, or (for the first episodes of a run with `--frames`, see
    `openral_mjx.evaluation.frames`) one entry per sensor, `{"sensor", "file", "array",
    "shape", "dtype", "reproduced"}`: its readings at every step from the reset state to the
    episode's end, stored as `array` in the `.npz` `file` beside the report.
    """

    success: bool
    steps: int
    total_reward: float
    mean_step_latency_ms: float
    max_step_latency_ms: float
    latency_budget_ms: float
    budget_violations: int
    frames: list[Any] | None = None
    metadata: dict[str, Any] = dataclasses.field(default_factory=dict)

    def summary(self) -> str:
        """One human-readable line."""
        outcome = (
            "success"
            if self.success
            else ("diverged" if self.metadata.get("diverged") else "failure")
        )
        return (
            f"seed {self.metadata.get('seed')}: {outcome} in {self.steps} steps, "
            f"reward {self.total_reward:.2f}"
        )


@dataclasses.dataclass
class TaskRow:
    """Per-task aggregate (one row per task; a single-task scene has one); `instruction` is
    the task in natural language (the scene's `instruction`), None in reports before /5."""

    task: str
    n_episodes: int
    successes: int
    success_rate: float
    ci_low: float
    ci_high: float
    instruction: str | None = None


@dataclasses.dataclass
class BreakdownRow:
    """Success within one bin of one episode factor: episodes with `low <= value < high`
    (`<= high` in a factor's last bin), with a Wilson interval at the report's confidence."""

    factor: str
    low: float
    high: float
    n: int
    successes: int
    rate: float
    ci_low: float
    ci_high: float


@dataclasses.dataclass
class SequentialInfo:
    """How a sequential run (`eval --target-halfwidth`) stopped, and the rule it followed.

    Looks came after every `chunk` episodes up to `max_episodes`; the run stopped after
    `looks` of them because the target was met (`stopped` = "target") or at the cap
    ("max_episodes"). `halfwidth` is that of the reported interval, which is exact for this
    design (`rule`), not a fixed-n interval.
    """

    target_halfwidth: float
    max_episodes: int
    chunk: int
    looks: int
    stopped: str
    halfwidth: float
    rule: str


@dataclasses.dataclass
class PartialInfo:
    """Why a report holds only part of its run, and which part (`eval --resume` finishes it).

    `reason` is e.g. "interrupted (SIGINT)" or "terminated (SIGTERM)"; `done` of `total`
    `unit`s finished ("episodes": always the first `done` seeds, a contiguous prefix; "tasks"
    and "points": `finished` names them, as the suite lists its tasks and as `%g` formats a
    sweep's values). The report's counts and intervals are over what finished only.
    """

    reason: str
    unit: str
    done: int
    total: int
    finished: list[str] = dataclasses.field(default_factory=list)

    def describe(self) -> str:
        """E.g. "2 of 4 points"."""
        return f"{self.done} of {self.total} {self.unit}"

    def summary(self) -> str:
        """E.g. "partial: interrupted (SIGINT), 2 of 4 points"."""
        return f"partial: {self.reason}, {self.describe()}"


@dataclasses.dataclass
class EvalReport:
    """Aggregate of one evaluation run; `episodes` holds every `EpisodeResult`.

    `ci_method` is "wilson" for a fixed number of episodes and "sequential-exact" for a
    sequential run (see `sequential`). `breakdown` holds success per bin of each episode
    factor the scene declares (equal-count bins). Throughput over `run_s`: `env_steps_per_s`
    counts every env-step the batch simulated (finished envs waiting included),
    `live_env_steps_per_s` only the steps of running episodes, `episodes_per_s` episodes.
    `instruction` is the task in natural language, as language-conditioned policies were told
    it (None for a suite, whose `per_task` rows carry each task's, and in reports before /5).
    `partial` is None for a complete run, else what an interrupted one kept (`PartialInfo`);
    `mujoco_warnings` counts MuJoCo C's warnings during the run by kind (e.g. "BADQACC"): the
    messages MuJoCo would have printed (see `physics.mj_warnings`), counted instead.
    """

    scene: str
    task: str
    robot: str
    policy: str
    backend: str
    device: str
    n_episodes: int
    n_envs: int
    seed: int
    max_steps: int
    successes: int
    success_rate: float
    ci_low: float
    ci_high: float
    confidence: float
    ci_method: str
    diverged: int
    per_task: list[TaskRow]
    breakdown: list[BreakdownRow]
    env_steps_per_s: float
    episodes_per_s: float
    compile_s: float
    run_s: float
    control_dt_s: float
    options: dict[str, Any]
    versions: dict[str, str]
    command: str
    created_at: str
    episodes: list[EpisodeResult]
    sequential: SequentialInfo | None = None
    live_env_steps_per_s: float | None = None
    instruction: str | None = None
    partial: PartialInfo | None = None
    mujoco_warnings: dict[str, int] = dataclasses.field(default_factory=dict)
    schema_version: str = SCHEMA_VERSION

    def summary(self) -> str:
        """The one-line human summary printed by the CLI."""
        pct = 100 * self.success_rate
        div = f", {self.diverged} diverged" if self.diverged else ""
        return (
            f"{self.scene}/{self.policy} on {self.backend}: success {pct:.1f}% "
            f"[{100 * self.ci_low:.1f}, {100 * self.ci_high:.1f}] ({self.ci_method} "
            f"{round(100 * self.confidence)}%), {self.successes}/{self.n_episodes} episodes"
            f"{div}, {self.env_steps_per_s:,.0f} env-steps/s, compile {self.compile_s:.1f} s"
            + ("" if self.partial is None else f"; {self.partial.summary()}")
        )

    def to_dict(self) -> dict[str, Any]:
        """JSON-ready dict (episodes converted shallowly: `asdict` deep-copies, slow at 100k)."""
        out: dict[str, Any] = {}
        for f in dataclasses.fields(self):
            value = getattr(self, f.name)
            out[f.name] = dataclasses.asdict(value) if dataclasses.is_dataclass(value) else value
        out["per_task"] = [dataclasses.asdict(r) for r in self.per_task]
        out["breakdown"] = [dataclasses.asdict(r) for r in self.breakdown]
        names = [f.name for f in dataclasses.fields(EpisodeResult)]
        out["episodes"] = [{k: getattr(e, k) for k in names} for e in self.episodes]
        return out

    @classmethod
    def from_dict(cls, data: dict[str, Any]) -> EvalReport:
        """Strict: another schema version, a missing or an unknown field is a `ConfigError`."""
        version = data.get("schema_version") if isinstance(data, dict) else None
        if version not in READABLE_VERSIONS:
            raise ConfigError(
                f"schema {version!r} is not supported; valid: {', '.join(READABLE_VERSIONS)}"
            )
        data = dict(data)
        for name in ("per_task", "breakdown", "episodes"):
            if name in data and not isinstance(data[name], list):
                raise ConfigError(f"{name} must be a list, got {type(data[name]).__name__}")
        for name, row in (("per_task", TaskRow), ("breakdown", BreakdownRow)):
            if name in data:
                data[name] = [_build(row, r, name) for r in data[name]]
        if data.get("sequential") is not None:
            data["sequential"] = _build(SequentialInfo, data["sequential"], "sequential")
        if data.get("partial") is not None:
            data["partial"] = _build(PartialInfo, data["partial"], "partial")
        if "episodes" in data:
            data["episodes"] = [_build(EpisodeResult, e, "episodes") for e in data["episodes"]]
        return _build(cls, data, "report")


def _build(cls: type, data: Any, where: str) -> Any:
    """`cls(**data)`, or a `ConfigError` naming unknown and missing fields."""
    if not isinstance(data, dict):
        raise ConfigError(f"{where}: expected an object, got {type(data).__name__}")
    fields = dataclasses.fields(cls)
    unknown = sorted(set(data) - {f.name for f in fields})
    missing = [
        f.name
        for f in fields
        if f.name not in data
        and f.default is dataclasses.MISSING
        and f.default_factory is dataclasses.MISSING
    ]
    if unknown or missing:
        raise ConfigError(f"{where}: unknown fields {unknown}, missing fields {missing}")
    return cls(**data)
