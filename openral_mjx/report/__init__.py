"""The evaluation report: per-seed `EpisodeResult`s and the aggregate `EvalReport` (a
versioned JSON schema), written atomically and read back with checks."""

from openral_mjx.report.io import load_report, report_json, save_report
from openral_mjx.report.schema import (
    READABLE_VERSIONS,
    SCHEMA_VERSION,
    BreakdownRow,
    ClusterInfo,
    DecisionInfo,
    DecisionLook,
    EpisodeResult,
    EvalReport,
    PartialInfo,
    PartPlacement,
    SequentialInfo,
    TaskRow,
)

__all__ = [
    "READABLE_VERSIONS",
    "SCHEMA_VERSION",
    "BreakdownRow",
    "ClusterInfo",
    "DecisionInfo",
    "DecisionLook",
    "EpisodeResult",
    "EvalReport",
    "PartPlacement",
    "PartialInfo",
    "SequentialInfo",
    "TaskRow",
    "load_report",
    "report_json",
    "save_report",
]
