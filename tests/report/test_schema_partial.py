"""Schema /6 and sweep /2: a partial report and MuJoCo warning counts round-trip, older
versions still read, and a partial report says so in its summary line."""

import dataclasses
import json
from pathlib import Path

from openral_mjx.report import EvalReport, PartialInfo, load_report, save_report
from openral_mjx.report.sweep import load_sweep, save_sweep

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
