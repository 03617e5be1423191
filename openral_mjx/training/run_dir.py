"""A training run's directory: its settings, metrics log, resumable checkpoints, policies.

    OUT/run.json            settings of the run (what `--resume` continues)
    OUT/metrics.jsonl       one JSON object per update ("train") and per evaluation ("eval")
    OUT/state/update_N/     full training state after update N (orbax `arrays/` + progress.json)
    OUT/init/, OUT/best/, OUT/final/   `mlp` policy checkpoints: the starting policy, the best
                            by validation success, and the last
    OUT/summary.json        the finished run's summary (final against initial, paired)

Each checkpoint is built in a temporary directory and renamed into place when complete, so an
interrupted save leaves the previous checkpoint as the latest.
"""

from __future__ import annotations

import json
import os
import shutil
from pathlib import Path
from typing import Any

from openral_mjx.core.checkpoints import restore_tree, save_tree
from openral_mjx.core.errors import ConfigError
from openral_mjx.core.files import write_json_atomic

RUN_FORMAT = "openral_mjx.ppo_run/1"


class RunDir:
    """Files of one run under `path`."""

    def __init__(self, path: Path) -> None:
        self.path = Path(path)
        self.settings_path = self.path / "run.json"
        self.metrics_path = self.path / "metrics.jsonl"
        self.state_dir = self.path / "state"
        self.init = self.path / "init"
        self.best = self.path / "best"
        self.final = self.path / "final"
        self.curve_path = self.path / "learning_curve.png"
        self.summary_path = self.path / "summary.json"

    # ---- settings --------------------------------------------------------------------------

    def create(self, settings: dict[str, Any]) -> None:
        """Start a new run here; refuse a directory holding a run with checkpoints (one that
        stopped before its first checkpoint is started afresh)."""
        if self.settings_path.exists() and self.latest_update() is not None:
            raise ConfigError(
                f"--out {str(self.path)!r} already holds a run; pass --resume to continue it, "
                "or choose another --out"
            )
        if self.path.exists() and not self.path.is_dir():
            raise ConfigError(f"--out {str(self.path)!r} is a file; give a directory")
        write_json_atomic(self.settings_path, {"format": RUN_FORMAT, **settings})
        self.metrics_path.unlink(missing_ok=True)

    def load_settings(self) -> dict[str, Any]:
        if not self.settings_path.is_file():
            raise ConfigError(f"no run in {str(self.path)!r} (no run.json)")
        try:
            data = json.loads(self.settings_path.read_text())
        except json.JSONDecodeError as e:
            path = str(self.settings_path)
            raise ConfigError(f"{path!r} is not valid JSON: {e}") from None
        if data.pop("format", None) != RUN_FORMAT:
            raise ConfigError(f"{str(self.settings_path)!r} is not a {RUN_FORMAT} file")
        return data

    def save_settings(self, settings: dict[str, Any]) -> None:
        write_json_atomic(self.settings_path, {"format": RUN_FORMAT, **settings})

    # ---- metrics log -----------------------------------------------------------------------

    def append_metrics(self, row: dict[str, Any]) -> None:
        with self.metrics_path.open("a") as f:
            f.write(json.dumps(row, allow_nan=False) + "\n")

    def read_metrics(self) -> list[dict[str, Any]]:
        if not self.metrics_path.is_file():
            return []
        return [json.loads(line) for line in self.metrics_path.read_text().splitlines() if line]

    def truncate_metrics(self, last_update: int) -> list[dict[str, Any]]:
        """Drop rows logged after `last_update` (work lost to an interruption); return the rest."""
        rows = [r for r in self.read_metrics() if r["update"] <= last_update]
        tmp = self.metrics_path.with_name(f".{self.metrics_path.name}.tmp")
        tmp.write_text("".join(json.dumps(r) + "\n" for r in rows))
        os.replace(tmp, self.metrics_path)
        return rows

    # ---- training-state checkpoints --------------------------------------------------------

    def _checkpoints(self) -> list[tuple[int, Path]]:
        if not self.state_dir.is_dir():
            return []
        found = []
        for p in self.state_dir.iterdir():
            if p.name.startswith("update_") and (p / "progress.json").is_file():
                found.append((int(p.name.removeprefix("update_")), p))
        return sorted(found)

    def save_state(self, update: int, tree: Any, progress: dict[str, Any], keep: int) -> None:
        """Checkpoint the training state after `update`, keeping the newest `keep`."""
        final = self.state_dir / f"update_{update:07d}"
        tmp = self.state_dir / f".tmp_update_{update:07d}"
        shutil.rmtree(tmp, ignore_errors=True)
        digests = save_tree(tmp / "arrays", tree)
        write_json_atomic(tmp / "progress.json", {**progress, "arrays_sha256": digests})
        shutil.rmtree(final, ignore_errors=True)
        tmp.rename(final)
        for _, old in self._checkpoints()[:-keep]:
            shutil.rmtree(old, ignore_errors=True)

    def latest_update(self) -> int | None:
        found = self._checkpoints()
        return found[-1][0] if found else None

    def load_state(self, template: Any) -> tuple[Any, dict[str, Any]]:
        """The newest checkpoint, restored onto `template`, and its progress record."""
        found = self._checkpoints()
        if not found:
            raise ConfigError(f"no checkpoint under {str(self.state_dir)!r}")
        _, path = found[-1]
        try:
            progress = json.loads((path / "progress.json").read_text())
        except json.JSONDecodeError as e:
            raise ConfigError(f"checkpoint {str(path)!r}: progress.json is corrupt: {e}") from None
        digests = progress.pop("arrays_sha256", None)
        tree = restore_tree(path / "arrays", template, f"checkpoint {str(path)!r}", digests)
        return tree, progress
