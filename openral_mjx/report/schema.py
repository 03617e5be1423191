"""Episode results and evaluation reports: dataclasses, JSON (de)serialisation, versioned.

Field names follow the predecessor's `EpisodeResult` (success, steps, total_reward, latency
fields, frames, metadata). `EvalReport` aggregates a run; `SCHEMA_VERSION` changes whenever a
field's meaning or presence changes. Reports of `READABLE_VERSIONS` load (keeping their own
version); any other version is an error. Reading validates: the dataclasses below are the
typed model pydantic checks a report's JSON against (`report.validation`), then the counts
are checked to add up (`check_totals`).
"""

from __future__ import annotations

import dataclasses
import json
from functools import cache
from typing import Any, ClassVar

from pydantic import ConfigDict, TypeAdapter

from openral_mjx.core.errors import ConfigError
from openral_mjx.report.validation import (
    STRICT,
    Count,
    Fraction,
    check,
    validate_data,
    validate_json,
)

SCHEMA_VERSION = "openral_mjx.eval_report/9"
# /2 has the same fields as /3; /3 only widened what the latency fields and metadata may hold
# (a torch policy's own latencies, a host worker's error), so a /2 report reads as it was.
# /4 added `live_env_steps_per_s` (continuous batching), None when read from /2 or /3.
# /5 added `instruction` (the report's and each per-task row's), None when read from /2../4.
# /6 added `partial` (an interrupted run's report of what finished; None: complete) and
# `mujoco_warnings` (MuJoCo's warnings by kind), None and {} when read from /2../5.
# /7 added `decision` (a sequential paired comparison's design, looks and verdict) and
# `cluster` (where a suite's tasks ran on a Ray cluster), None when read from /2../6.
# /8 added `build_s` (seconds building the scene and the policy before compiling), {} when
# read from /2../7.
# /9 added `overflowed` (diverged episodes whose engine buffers overflowed), 0 when read from
# /2../8.
READABLE_VERSIONS = (
    "openral_mjx.eval_report/2",
    "openral_mjx.eval_report/3",
    "openral_mjx.eval_report/4",
    "openral_mjx.eval_report/5",
    "openral_mjx.eval_report/6",
    "openral_mjx.eval_report/7",
    "openral_mjx.eval_report/8",
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
    `metadata` carries seed, scene, task, robot, policy, backend, diverged (and, for a diverged
    episode whose backend says, overflowed: whether an engine buffer ran out), first_success_step,
    `factors` (the scene's randomised factors of this episode, name -> value) and, for host
    scenes, `error` (why a worker fault ended the episode, or null).
    `frames` is None, or (for the first episodes of a run with `--frames`, see
    `openral_mjx.evaluation.frames`) one entry per sensor, `{"sensor", "file", "array",
    "shape", "dtype", "reproduced"}`: its readings at every step from the reset state to the
    episode's end, stored as `array` in the `.npz` `file` beside the report.
    """

    __pydantic_config__: ClassVar[ConfigDict] = STRICT

    success: bool
    steps: Count
    total_reward: float
    mean_step_latency_ms: float
    max_step_latency_ms: float
    latency_budget_ms: float
    budget_violations: Count
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

    __pydantic_config__: ClassVar[ConfigDict] = STRICT

    task: str
    n_episodes: Count
    successes: Count
    success_rate: Fraction
    ci_low: Fraction
    ci_high: Fraction
    instruction: str | None = None


@dataclasses.dataclass
class BreakdownRow:
    """Success within one bin of one episode factor: episodes with `low <= value < high`
    (`<= high` in a factor's last bin), with a Wilson interval at the report's confidence."""

    __pydantic_config__: ClassVar[ConfigDict] = STRICT

    factor: str
    low: float
    high: float
    n: Count
    successes: Count
    rate: Fraction
    ci_low: Fraction
    ci_high: Fraction


@dataclasses.dataclass
class SequentialInfo:
    """How a sequential run (`eval --target-halfwidth`) stopped, and the rule it followed.

    Looks came after every `chunk` episodes up to `max_episodes`; the run stopped after
    `looks` of them because the target was met (`stopped` = "target") or at the cap
    ("max_episodes"). `halfwidth` is that of the reported interval, which is exact for this
    design (`rule`), not a fixed-n interval.
    """

    __pydantic_config__: ClassVar[ConfigDict] = STRICT

    target_halfwidth: float
    max_episodes: Count
    chunk: Count
    looks: Count
    stopped: str
    halfwidth: float
    rule: str


@dataclasses.dataclass
class DecisionLook:
    """One look of a sequential paired comparison (`eval --decide`): over the first `n` seeds,
    `only_a` / `only_b` the seeds only A / only B succeeded on; the test of no difference stops
    with "better" where `only_b >= upper`, "worse" where `only_b <= lower`."""

    __pydantic_config__: ClassVar[ConfigDict] = STRICT

    n: Count
    only_a: Count
    only_b: Count
    lower: int
    upper: int


@dataclasses.dataclass
class DecisionInfo:
    """How a sequential paired comparison (`eval --compare-with A.json --decide`) ran and what
    it decided: B against `baseline` (A's report, policy `baseline_policy`) on the same seeds,
    looks after every `chunk` seeds up to `cap`, under `rule` (the design in words, with
    `alpha`, equivalence `margin` and `spending`). `decision`: "better", "worse",
    "equivalent" (B - A within +-margin), "inconclusive" (the cap came first); in a
    partial report (an interrupted run, `eval --resume` finishes it) "undecided", over the
    looks before the interrupt. [`ci_low`, `ci_high`]: the repeated interval for
    rate_B - rate_A at the last look, valid under the stopping rule (coverage >= 1 - alpha);
    `difference` the observed B - A."""

    __pydantic_config__: ClassVar[ConfigDict] = STRICT

    baseline: str
    baseline_policy: str
    rule: str
    alpha: float
    margin: float | None
    spending: str
    chunk: Count
    cap: Count
    looks: list[DecisionLook]
    decision: str
    difference: float
    ci_low: float
    ci_high: float


@dataclasses.dataclass
class PartialInfo:
    """Why a report holds only part of its run, and which part (`eval --resume` finishes it).

    `reason` is e.g. "interrupted (SIGINT)" or "terminated (SIGTERM)"; `done` of `total`
    `unit`s finished ("episodes": always the first `done` seeds, a contiguous prefix; "tasks"
    and "points": `finished` names them, as the suite lists its tasks and as `%g` formats a
    sweep's values). The report's counts and intervals are over what finished only.
    """

    __pydantic_config__: ClassVar[ConfigDict] = STRICT

    reason: str
    unit: str
    done: Count
    total: Count
    finished: list[str] = dataclasses.field(default_factory=list)

    def describe(self) -> str:
        """E.g. "2 of 4 points"."""
        return f"{self.done} of {self.total} {self.unit}"

    def summary(self) -> str:
        """E.g. "partial: interrupted (SIGINT), 2 of 4 points"."""
        return f"partial: {self.reason}, {self.describe()}"


@dataclasses.dataclass
class PartPlacement:
    """Where one part of a cluster run (a suite's task) ran: the Ray node that finished it
    (`node_id`, `node_ip`) and `attempts`, 1 when its first run finished; each worker or node
    that died under it added one (the part ran again from the start, elsewhere or there)."""

    __pydantic_config__: ClassVar[ConfigDict] = STRICT

    part: str
    node_id: str
    node_ip: str
    attempts: Count


@dataclasses.dataclass
class ClusterInfo:
    """A run fanned out over a Ray cluster (`eval --cluster`): the `address` given, the
    `nodes` alive when it started, the `retries` (attempts beyond each part's first) and
    where each part ran, in the run's order. Per seed the episodes are a local run's."""

    __pydantic_config__: ClassVar[ConfigDict] = STRICT

    address: str
    nodes: Count
    retries: Count
    parts: list[PartPlacement]

    def summary(self) -> str:
        """E.g. "cluster auto: 10 parts on 2 of 2 nodes (127.0.0.1), 1 retry"."""
        ips = sorted({p.node_ip for p in self.parts})
        used = len({p.node_id for p in self.parts})
        return (
            f"cluster {self.address}: {len(self.parts)} parts on {used} of {self.nodes} "
            f"nodes ({', '.join(ips)}), {self.retries} retr{'y' if self.retries == 1 else 'ies'}"
        )


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
    `cluster` is None for a run on this machine, else where its parts ran (`ClusterInfo`).
    `build_s` is what came before `compile_s`: seconds building the `scene` and the `policy`
    (with its parameters), by what the run built (a suite's: summed over its tasks; a policy
    kept from an earlier task counts only its parameters), so that start-up is accounted for.
    `overflowed` counts the `diverged` episodes whose physics engine ran out of buffer room
    (MuJoCo-Warp's contacts or constraints: a capacity to raise, `--contacts-per-env`), and
    each such episode's metadata says ``overflowed`` true.
    """

    __pydantic_config__: ClassVar[ConfigDict] = STRICT

    scene: str
    task: str
    robot: str
    policy: str
    backend: str
    device: str
    n_episodes: Count
    n_envs: Count
    seed: Count
    max_steps: Count
    successes: Count
    success_rate: Fraction
    ci_low: Fraction
    ci_high: Fraction
    confidence: Fraction
    ci_method: str
    diverged: Count
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
    decision: DecisionInfo | None = None
    cluster: ClusterInfo | None = None
    build_s: dict[str, float] = dataclasses.field(default_factory=dict)
    overflowed: Count = 0
    schema_version: str = SCHEMA_VERSION

    def summary(self) -> str:
        """The one-line human summary printed by the CLI."""
        pct = 100 * self.success_rate
        div = f", {self.diverged} diverged" if self.diverged else ""
        if self.overflowed:
            div += (
                f" ({self.overflowed} from full physics buffers: raise --contacts-per-env or "
                "--ccd-contacts-per-env)"
            )
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
    def from_dict(cls, data: Any) -> EvalReport:
        """Strict: another schema version, a wrong type, a missing or unknown field, or counts
        that do not add up is a `ConfigError` naming the field."""
        _check_version(data)
        report = validate_data(_adapter(), data)
        check_totals(report)
        return report

    @classmethod
    def from_json(cls, text: str) -> EvalReport:
        """`from_dict` of JSON `text`, validated from the text itself (no second encoding)."""
        try:
            data = json.loads(text)
        except json.JSONDecodeError as e:
            raise ConfigError(f"not valid JSON: {e}") from None
        _check_version(data)
        report = validate_json(_adapter(), text)
        check_totals(report)
        return report


def _check_version(data: Any) -> None:
    version = data.get("schema_version") if isinstance(data, dict) else None
    if version not in READABLE_VERSIONS:
        raise ConfigError(
            f"schema {version!r} is not supported; valid: {', '.join(READABLE_VERSIONS)}"
        )


@cache
def _adapter() -> TypeAdapter[EvalReport]:
    return TypeAdapter(EvalReport)


def check_totals(report: EvalReport) -> None:
    """What the types cannot say: the totals agree with the episodes and the per-task rows
    (`ConfigError` naming the field)."""
    n, k = report.n_episodes, report.successes
    check(k <= n, f"successes {k} > n_episodes {n}")
    check(report.diverged <= n, f"diverged {report.diverged} > n_episodes {n}")
    check(
        report.overflowed <= report.diverged,
        f"overflowed {report.overflowed} > diverged {report.diverged}",
    )
    check(len(report.episodes) == n, f"episodes holds {len(report.episodes)}, n_episodes is {n}")
    won = sum(e.success for e in report.episodes)
    check(won == k, f"successes is {k}, but {won} episodes have success true")
    rate = k / n if n else 0.0
    check(abs(report.success_rate - rate) <= 1e-9, f"success_rate {report.success_rate} != {rate}")
    check(report.ci_low <= report.ci_high, f"ci_low {report.ci_low} > ci_high {report.ci_high}")
    for i, row in enumerate(report.per_task):
        check(row.successes <= row.n_episodes, f"per_task[{i}].successes > its n_episodes")
    rows = sum(r.n_episodes for r in report.per_task)
    check(rows == n, f"per_task rows hold {rows} episodes, n_episodes is {n}")
    for i, row in enumerate(report.breakdown):
        check(row.successes <= row.n, f"breakdown[{i}].successes > its n")
