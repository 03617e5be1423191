"""Sensor frames of a run's first episodes: re-simulated, saved beside the report, read back.

The evaluation records nothing per step (it must not slow down for frames nobody asked for);
an episode is a function of its seed, so the first K seeds are run again with the runner's
tracing variant, as for videos (`viz.record`), and their sensor readings (`Scene.sensor_frames`)
at every step, from the reset state to the episode's end, go into one `.npz` beside the
report: depth images and laser ranges in metres as float32 (bit for bit what the policy
observed), RGB images as uint8. Each recorded episode's `EpisodeResult.frames` names its
arrays and says whether the re-simulation reproduced the evaluated episode exactly.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from openral_mjx.core.errors import ConfigError
from openral_mjx.core.files import atomic_path
from openral_mjx.evaluation.replay import choose_seeds, trace_episodes
from openral_mjx.evaluation.run import Evaluation
from openral_mjx.report import EvalReport
from openral_mjx.scenes import Scene


def check_frames(scene: Scene, k: int) -> None:
    """Reject a negative K, and K > 0 on a scene that observes no sensors (`ConfigError`)."""
    if k < 0:
        raise ConfigError(f"frames must be >= 0, got {k}")
    if k and not scene.sensor_shapes:
        raise ConfigError(
            f"frames: scene {scene.name!r} observes no sensors; add some with its obs_* options "
            "(e.g. --opt 'obs_depth_cameras=[overhead]')"
        )


def _stored(reading: np.ndarray) -> np.ndarray:
    """RGB (..., 3) in [0, 1] as uint8; ranges (metres) as float32."""
    if reading.ndim == 4 and reading.shape[-1] == 3:
        return np.round(255 * np.clip(reading, 0, 1)).astype(np.uint8)
    return reading.astype(np.float32)


def record_frames(evaluation: Evaluation, k: int, file: str) -> dict[str, np.ndarray]:
    """Re-simulate the first `k` episodes of `evaluation`, reference their frames from their
    `EpisodeResult.frames` (stored as `file`, a name beside the report) and return the arrays
    by name (`seed{S}/{sensor}`), for `save_frames`."""
    check_frames(evaluation.scene, k)
    report = evaluation.report
    index = {e.metadata["seed"]: e for e in report.episodes}
    arrays: dict[str, np.ndarray] = {}
    for trace in trace_episodes(evaluation, choose_seeds(evaluation, first=k)):
        episode = index[trace.seed]
        episode.frames = []
        for sensor, reading in trace.sensors.items():
            data = _stored(reading)
            name = f"seed{trace.seed}/{sensor}"
            arrays[name] = data
            episode.frames.append(
                {
                    "sensor": sensor,
                    "file": file,
                    "array": name,
                    "shape": list(data.shape),
                    "dtype": str(data.dtype),
                    "reproduced": trace.reproduced,
                }
            )
    return arrays


def save_frames(path: Path, arrays: dict[str, np.ndarray]) -> None:
    """Write recorded frames to `path` (`.npz`, compressed) atomically."""
    with atomic_path(path) as tmp, tmp.open("wb") as f:
        np.savez_compressed(f, **arrays)


def load_frames(path: Path, report: EvalReport) -> dict[int, dict[str, np.ndarray]]:
    """The recorded frames of the report saved at `path`: seed -> sensor -> (steps + 1, ...)
    array. A missing frames file, or one without an episode's array, is a `ConfigError`."""
    out: dict[int, dict[str, np.ndarray]] = {}
    files: dict[str, dict[str, np.ndarray]] = {}
    for e in report.episodes:
        for f in e.frames or ():
            if f["file"] not in files:
                file = path.parent / f["file"]
                if not file.is_file():
                    raise ConfigError(f"frames file {str(file)!r} does not exist")
                with np.load(file) as npz:
                    files[f["file"]] = {name: npz[name] for name in npz.files}
            if f["array"] not in files[f["file"]]:
                raise ConfigError(f"frames file {f['file']!r} lacks {f['array']!r}")
            out.setdefault(e.metadata["seed"], {})[f["sensor"]] = files[f["file"]][f["array"]]
    return out
