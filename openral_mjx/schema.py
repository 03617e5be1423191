"""Episode results and evaluation reports: dataclasses, JSON (de)serialisation, versioned.

Field names follow the predecessor's `EpisodeResult` (success, steps, total_reward, latency
fields, frames, metadata). `EvalReport` aggregates a run; `SCHEMA_VERSION` changes whenever a
field's meaning or presence changes, and loading a report of another version is an error.
"""

from __future__ import annotations

import dataclasses
import json
import os
import tempfile
from pathlib import Path
from typing import Any

from openral_mjx.errors import ConfigError

SCHEMA_VERSION = "openral_mjx.eval_report/1"


@dataclasses.dataclass
class EpisodeResult:
    """Outcome of one episode (one seed).

    Latencies are per control step of the whole batch (the batch advances in lock-step under
    one `jit`), measured per chunk: `mean_step_latency_ms` = chunk wall time / scanned steps,
    and `max_step_latency_ms` the largest such chunk mean over the run (per-step timing inside
    a fused scan is not observable). `latency_budget_ms` is the scene's control period;
    `budget_violations` counts this episode's steps taken while the batch step was slower.
    `metadata` carries seed, scene, task, robot, policy, backend, diverged, first_success_step.
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
    """Per-task aggregate (one row per task; a single-task scene has one)."""

    task: str
    n_episodes: int
    successes: int
    success_rate: float
    ci_low: float
    ci_high: float


@dataclasses.dataclass
class EvalReport:
    """Aggregate of one evaluation run; `episodes` holds every `EpisodeResult`."""

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
        )

    def to_dict(self) -> dict[str, Any]:
        return dataclasses.asdict(self)

    @classmethod
    def from_dict(cls, data: dict[str, Any]) -> EvalReport:
        version = data.get("schema_version")
        if version != SCHEMA_VERSION:
            raise ConfigError(
                f"report schema {version!r} is not supported; valid: {SCHEMA_VERSION}"
            )
        fields = {f.name for f in dataclasses.fields(cls)}
        unknown = sorted(set(data) - fields)
        if unknown:
            raise ConfigError(f"report has unknown fields {unknown}")
        data = dict(data)
        data["per_task"] = [TaskRow(**r) for r in data["per_task"]]
        data["episodes"] = [EpisodeResult(**e) for e in data["episodes"]]
        return cls(**data)


def write_json_atomic(path: Path, data: Any) -> None:
    """Write JSON to `path` via a temporary file and `os.replace`: never half-written."""
    path.parent.mkdir(parents=True, exist_ok=True)
    fd, tmp = tempfile.mkstemp(prefix=f".{path.name}.", suffix=".tmp", dir=path.parent)
    try:
        with os.fdopen(fd, "w") as f:
            json.dump(data, f, indent=1, allow_nan=False)
            f.write("\n")
        os.replace(tmp, path)
    except BaseException:
        Path(tmp).unlink(missing_ok=True)
        raise


def save_report(report: EvalReport, path: Path) -> None:
    write_json_atomic(path, report.to_dict())


def load_report(path: Path) -> EvalReport:
    if not path.is_file():
        raise ConfigError(f"report {str(path)!r} does not exist")
    try:
        data = json.loads(path.read_text())
    except json.JSONDecodeError as e:
        raise ConfigError(f"report {str(path)!r} is not valid JSON: {e}") from None
    return EvalReport.from_dict(data)
