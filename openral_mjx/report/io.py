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


def check_readable(path: Path, what: str) -> None:
    """A `ConfigError` unless `path` is a file to read: a directory is named as one."""
    if path.is_dir():
        raise ConfigError(f"{what} {str(path)!r} is a directory, not a report file")
    if not path.is_file():
        raise ConfigError(f"{what} {str(path)!r} does not exist")


def load_report(path: Path | str) -> EvalReport:
    """Read a report back, validated (`EvalReport.from_json`): every problem (missing file,
    a directory, bad JSON, another schema version, a wrong type, a missing or unknown field,
    counts that do not add up) is a one-line `ConfigError` naming the file and the field."""
    path = Path(path)
    check_readable(path, "report")
    try:
        return EvalReport.from_json(path.read_text())
    except ConfigError as e:
        raise ConfigError(f"report {str(path)!r}: {e}") from None
    except (OSError, UnicodeDecodeError) as e:
        raise ConfigError(f"report {str(path)!r} cannot be read: {e}") from None
