"""Reports on disk: written atomically as JSON (one line per episode), read back with checks."""

from __future__ import annotations

import json
from pathlib import Path

from openral_mjx.core.errors import ConfigError
from openral_mjx.core.files import write_text_atomic
from openral_mjx.report.schema import EvalReport


def report_json(report: EvalReport) -> str:
    """The report as indented JSON with one compact line per episode, so that a report of
    100,000 episodes stays a file of tens of MB that a line-oriented tool can still read."""
    data = report.to_dict()
    episodes = data.pop("episodes")
    head = json.dumps(data, indent=1, allow_nan=False)
    rows = ",\n  ".join(json.dumps(e, separators=(",", ":"), allow_nan=False) for e in episodes)
    body = f"\n  {rows}\n " if rows else ""
    return f'{head[:-2]},\n "episodes": [{body}]\n}}\n'


def save_report(report: EvalReport, path: Path) -> None:
    write_text_atomic(path, report_json(report))


def load_report(path: Path) -> EvalReport:
    """Read a report back; every problem (missing file, bad JSON, another schema version,
    unknown or missing fields) is a `ConfigError` that names the file."""
    if not path.is_file():
        raise ConfigError(f"report {str(path)!r} does not exist")
    try:
        data = json.loads(path.read_text())
    except json.JSONDecodeError as e:
        raise ConfigError(f"report {str(path)!r} is not valid JSON: {e}") from None
    try:
        return EvalReport.from_dict(data)
    except ConfigError as e:
        raise ConfigError(f"report {str(path)!r}: {e}") from None
