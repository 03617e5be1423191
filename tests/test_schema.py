"""Report JSON: round trip through a saved file, version check, atomic writes."""

import json

import pytest

from openral_mjx.errors import ConfigError
from openral_mjx.evaluate import evaluate
from openral_mjx.schema import SCHEMA_VERSION, EvalReport, load_report, save_report


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
    assert json.loads(path.read_text())["schema_version"] == SCHEMA_VERSION
    assert [p.name for p in tmp_path.iterdir()] == ["r.json"]  # no temp file left


def test_report_fields(report):
    assert report.n_episodes == 6 and len(report.episodes) == 6
    assert report.backend == "c" and report.device.startswith("cpu")
    e = report.episodes[0]
    assert e.steps == 3 and e.latency_budget_ms == pytest.approx(20.0)
    assert e.metadata["scene"] == "tabletop_push" and e.metadata["seed"] == 0
    assert report.versions["mujoco"] and report.per_task[0].n_episodes == 6
    assert "seed 0: failure in 3 steps" in e.summary()


def test_wrong_version_is_rejected(report, tmp_path):
    data = report.to_dict()
    data["schema_version"] = "openral_mjx.eval_report/0"
    path = tmp_path / "old.json"
    path.write_text(json.dumps(data))
    with pytest.raises(ConfigError, match="not supported"):
        load_report(path)


def test_failed_write_leaves_nothing(report, tmp_path):
    bad = report.to_dict()
    bad["success_rate"] = float("nan")  # not JSON: json.dump(allow_nan=False) raises
    from openral_mjx.schema import write_json_atomic

    with pytest.raises(ValueError):
        write_json_atomic(tmp_path / "x.json", bad)
    assert list(tmp_path.iterdir()) == []
