"""Report JSON: round trip through a saved file, strict loading, compact layout, atomic writes."""

import dataclasses
import json
import re
from pathlib import Path

import jax.numpy as jnp
import numpy as np
import pytest

from openral_mjx.core.errors import ConfigError
from openral_mjx.evaluation import evaluate
from openral_mjx.report import (
    READABLE_VERSIONS,
    SCHEMA_VERSION,
    ClusterInfo,
    EvalReport,
    PartPlacement,
    load_report,
    save_report,
)
from openral_mjx.runner import make_factor_fn


@pytest.fixture(scope="module")
def report() -> EvalReport:
    return evaluate(
        "tabletop_push",
        "zero",
        n_envs=4,
        n_episodes=6,
        max_steps=3,
        backend="c",
        threads=1,
        command="python -m openral_mjx.eval --policy zero",
    )


def test_round_trip(report, tmp_path):
    path = tmp_path / "r.json"
    save_report(report, path)
    loaded = load_report(path)
    assert loaded == report
    assert load_report(str(path)) == report  # a path as a string too (Python callers)
    assert json.loads(path.read_text())["schema_version"] == SCHEMA_VERSION
    assert [p.name for p in tmp_path.iterdir()] == ["r.json"]  # no temp file left


def test_cluster_record_round_trips(report, tmp_path):
    """Where a cluster run's parts ran (schema /7) is saved, read back and validated; a report
    without it (a local run, or one of /6) has None."""
    where = [PartPlacement("a", "n1", "10.0.0.1", 1), PartPlacement("b", "n2", "10.0.0.2", 2)]
    clustered = dataclasses.replace(report, cluster=ClusterInfo("auto", 2, 1, where))
    save_report(clustered, tmp_path / "r.json")
    assert load_report(tmp_path / "r.json").cluster == clustered.cluster
    assert clustered.cluster.summary() == (
        "cluster auto: 2 parts on 2 of 2 nodes (10.0.0.1, 10.0.0.2), 1 retry"
    )
    old = report.to_dict()
    del old["cluster"]
    old["schema_version"] = "openral_mjx.eval_report/6"
    assert EvalReport.from_dict(old).cluster is None
    bad = clustered.to_dict()
    bad["cluster"]["parts"][0]["attempts"] = -1
    with pytest.raises(ConfigError, match=r"cluster.parts\[0\].attempts"):
        EvalReport.from_dict(bad)


def test_build_seconds_are_recorded_and_older_reports_have_none(report, tmp_path):
    """The run built its scene and policy by name: both are timed (schema /8), saved and read
    back; a report of /7 has no such timings."""
    assert set(report.build_s) == {"scene", "policy"}
    assert all(0.0 < s < 600.0 for s in report.build_s.values()), report.build_s
    save_report(report, tmp_path / "r.json")
    assert load_report(tmp_path / "r.json").build_s == report.build_s
    old = report.to_dict()
    del old["build_s"]
    old["schema_version"] = "openral_mjx.eval_report/7"
    assert EvalReport.from_dict(old).build_s == {}
    bad = report.to_dict()
    bad["build_s"] = {**report.build_s, "scene": "slow"}
    with pytest.raises(ConfigError, match=r"build_s.scene"):
        EvalReport.from_dict(bad)


def test_report_fields(report):
    assert report.n_episodes == 6 and len(report.episodes) == 6
    assert report.backend == "c" and report.device.startswith("cpu")
    e = report.episodes[0]
    assert e.steps == 3 and e.latency_budget_ms == pytest.approx(20.0)
    assert e.metadata["scene"] == "tabletop_push" and e.metadata["seed"] == 0
    assert report.versions["mujoco"] and report.per_task[0].n_episodes == 6
    assert "seed 0: failure in 3 steps" in e.summary()
    assert report.sequential is None and report.ci_method == "wilson"


def test_report_records_the_instruction(report):
    """The scene's instruction, for the run and its task's row (schema /5)."""
    assert report.instruction == "push the red cube to the green goal"
    assert [r.instruction for r in report.per_task] == [report.instruction]


def test_breakdown_is_built_from_the_episodes_factors(report):
    factors = report.episodes[0].metadata["factors"]
    assert sorted(factors) == ["cube_x", "cube_y", "goal_distance", "push_face_angle"]
    for name in factors:
        rows = [r for r in report.breakdown if r.factor == name]
        values = [e.metadata["factors"][name] for e in report.episodes]
        assert sum(r.n for r in rows) == 6 and rows[0].low == min(values)
        assert rows[-1].high == max(values) and all(r.successes == 0 for r in rows)


def test_episode_values_are_lossless(report, push_c):
    """Factors and rewards read back to the runner's float32 values, bit for bit."""
    factors = make_factor_fn(push_c)(jnp.arange(6, dtype=jnp.int32))
    for name, values in factors.items():
        stored = np.array([e.metadata["factors"][name] for e in report.episodes], np.float32)
        np.testing.assert_array_equal(stored, values, err_msg=name)


def test_one_line_per_episode(report, tmp_path):
    path = tmp_path / "r.json"
    save_report(report, path)
    lines = path.read_text().splitlines()
    episode_lines = [ln for ln in lines if ln.lstrip().startswith('{"success":')]
    assert len(episode_lines) == 6
    assert json.loads(episode_lines[0].rstrip(","))["metadata"]["seed"] == 0


@pytest.mark.parametrize(
    "change,needle",
    [
        (lambda d: d.update(schema_version="openral_mjx.eval_report/1"), "not supported"),
        (lambda d: d.update(extra=1), "unknown field extra"),
        (lambda d: d.update(episodes=6), "field episodes: input should be a valid array, got 6"),
        (lambda d: d.pop("breakdown"), "field breakdown is missing"),
        (lambda d: d["episodes"][0].pop("steps"), "field episodes[0].steps is missing"),
        (lambda d: d["breakdown"][0].update(bin=3), "unknown field breakdown[0].bin"),
        # wrong types are refused, not coerced or counted
        (lambda d: d.update(successes="x"), "field successes: input should be a valid integer"),
        (lambda d: d["episodes"][1].update(success="maybe"), "field episodes[1].success: input"),
        (lambda d: d["episodes"][1].update(success=1), "field episodes[1].success: input"),
        (lambda d: d.update(n_episodes=6.0), "field n_episodes: input should be a valid integer"),
        (lambda d: d.update(success_rate=1.5), "field success_rate: input should be less than"),
        (lambda d: d["per_task"][0].update(successes=-1), "field per_task[0].successes: input"),
        # impossible counts
        (lambda d: d.update(successes=7), "successes 7 > n_episodes 6"),
        (lambda d: d.update(successes=1, success_rate=1 / 6), "but 0 episodes have success true"),
        (lambda d: d.update(diverged=9), "diverged 9 > n_episodes 6"),
        (lambda d: d["episodes"].pop(), "episodes holds 5, n_episodes is 6"),
        (lambda d: d.update(success_rate=0.5), "success_rate 0.5 != 0.0"),
        (lambda d: d["per_task"][0].update(n_episodes=5), "per_task rows hold 5 episodes"),
        (lambda d: d["breakdown"][0].update(successes=99), "breakdown[0].successes > its n"),
    ],
)
def test_loading_is_strict(report, tmp_path, change, needle):
    data = report.to_dict()
    change(data)
    path = tmp_path / "bad.json"
    path.write_text(json.dumps(data))
    with pytest.raises(ConfigError, match=r"^report '.*bad\.json': ") as exc:
        load_report(path)
    assert needle in str(exc.value) and "\n" not in str(exc.value), str(exc.value)
    with pytest.raises(ConfigError, match=re.escape(needle)):  # the same from a dict
        EvalReport.from_dict(data)


def test_a_directory_is_named_as_one(tmp_path):
    with pytest.raises(ConfigError, match="is a directory, not a report file"):
        load_report(tmp_path)


def _full_report(path: Path) -> bool:
    """A report of a readable schema that keeps its episodes (some saved ones drop them)."""
    data = json.loads(path.read_text())
    return (
        isinstance(data, dict)
        and data.get("schema_version") in READABLE_VERSIONS
        and isinstance(data.get("episodes"), list)
    )


SAVED_REPORTS = sorted(
    p for p in (Path(__file__).parents[2] / "benchmarks").rglob("*.json") if _full_report(p)
)


@pytest.mark.parametrize("path", SAVED_REPORTS, ids=lambda p: p.name)
def test_every_saved_report_validates(path):
    """Every full report kept in benchmarks/ (of any readable schema) passes validation."""
    loaded = load_report(path)
    assert loaded.n_episodes == len(loaded.episodes) > 0


SAVED_V2 = Path(__file__).parents[2] / "benchmarks/2026-11-23-ci2core/rays/box_c_nodepth.json"


def test_saved_schema_2_report_still_loads():
    """A /2 report (a saved CPU run of so101_box) reads as it was written."""
    raw = json.loads(SAVED_V2.read_text())
    loaded = load_report(SAVED_V2)
    assert loaded.schema_version == raw["schema_version"] == "openral_mjx.eval_report/2"
    assert loaded.successes == raw["successes"] == sum(e.success for e in loaded.episodes)
    assert len(loaded.episodes) == raw["n_episodes"]


def test_failed_write_leaves_nothing(report, tmp_path):
    bad = report.to_dict()
    bad["success_rate"] = float("nan")  # not JSON: json.dump(allow_nan=False) raises
    from openral_mjx.core.files import write_json_atomic

    with pytest.raises(ValueError):
        write_json_atomic(tmp_path / "x.json", bad)
    assert list(tmp_path.iterdir()) == []


def test_written_file_has_ordinary_permissions(tmp_path):
    import os
    import stat

    from openral_mjx.core.files import write_json_atomic

    path = tmp_path / "p.json"
    write_json_atomic(path, {"a": 1})
    mask = os.umask(0)
    os.umask(mask)
    assert stat.S_IMODE(path.stat().st_mode) == 0o666 & ~mask
