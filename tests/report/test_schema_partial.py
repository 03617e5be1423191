"""Schema /6 and sweep /2 and /4: a partial report, MuJoCo warning counts and a sweep point's
overflowed episodes round-trip, older versions still read, and a partial report says so in
its summary line."""

import dataclasses
import json
from pathlib import Path

import pytest

from openral_mjx.core.errors import ConfigError
from openral_mjx.report import EvalReport, PartialInfo, load_report, save_report
from openral_mjx.report.sweep import SWEEP_SCHEMA_VERSION, load_sweep, save_sweep

SAVED = Path(__file__).parents[2] / "benchmarks"
OLD_REPORT = SAVED / "2026-11-23-ci2core/rays/box_c_nodepth.json"  # schema /2
OLD_SWEEP = SAVED / "2026-11-25-cpu/sweep_tabletop_push_friction.json"  # sweep /1


def test_partial_report_round_trips_and_says_so(tmp_path):
    old = EvalReport.from_dict(json.loads(OLD_REPORT.read_text()))
    assert old.partial is None and old.mujoco_warnings == {}
    partial = PartialInfo("terminated (SIGTERM)", "episodes", old.n_episodes, 4 * old.n_episodes)
    report = dataclasses.replace(old, partial=partial, mujoco_warnings={"BADQACC": 3})
    path = tmp_path / "r.json"
    save_report(report, path)
    back = load_report(path)
    assert back.partial == partial and back.mujoco_warnings == {"BADQACC": 3}
    assert back.summary().endswith(
        f"; partial: terminated (SIGTERM), {old.n_episodes} of {4 * old.n_episodes} episodes"
    )
    assert "partial" not in old.summary()


def test_sweep_1_reads_and_a_partial_sweep_round_trips(tmp_path):
    old = load_sweep(OLD_SWEEP)
    assert old.schema_version == "openral_mjx.sweep/1" and old.partial is None
    finished = [f"{p.value:g}" for p in old.points[:2]]
    partial = PartialInfo("interrupted (SIGINT)", "points", 2, len(old.points), finished)
    cut = dataclasses.replace(old, points=old.points[:2], steps=old.steps[:1], partial=partial)
    path = tmp_path / "s.json"
    save_sweep(cut, path)
    back = load_sweep(path)
    assert back.partial == partial and back.points == old.points[:2]
    assert f"partial: interrupted (SIGINT), 2 of {len(old.points)} points" in back.summary()


def test_sweep_4_counts_a_points_overflowed_episodes_and_checks_them(tmp_path):
    old = load_sweep(OLD_SWEEP)
    assert all(p.overflowed == 0 for p in old.points)  # /1 has no such field: 0
    point = dataclasses.replace(old.points[0], diverged=3, overflowed=2)
    report = dataclasses.replace(
        old, points=[point, *old.points[1:]], schema_version=SWEEP_SCHEMA_VERSION
    )
    path = tmp_path / "s.json"
    save_sweep(report, path)
    back = load_sweep(path)
    assert back.points[0].overflowed == 2
    assert "3 diverged (2 from full physics buffers)" in back.summary()
    data = json.loads(path.read_text())
    data["points"][0]["overflowed"] = 4  # more than the point's 3 diverged
    path.write_text(json.dumps(data))
    with pytest.raises(ConfigError, match=r"points\[0\]\.overflowed > its diverged"):
        load_sweep(path)
