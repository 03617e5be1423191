"""The agreement table from stored reports (`agreement --from-reports`): each mirror report
paired seed by seed with its task's latest LIBERO report of the same protocol, rows in the
suites' order, and a mirror report with no such partner refused in one line."""

from __future__ import annotations

import dataclasses
import json

import numpy as np
import pytest
from report_variants import variant, with_steps
from worker_envs import require_worker_envs

from openral_mjx.benchmarks.libero.agreement import main, rows_from_reports
from openral_mjx.benchmarks.libero.assets import ENV
from openral_mjx.core.errors import ConfigError
from openral_mjx.evaluation import evaluate
from openral_mjx.report import EvalReport, save_report
from openral_mjx.stats import paired_comparison

require_worker_envs(ENV)  # the rows name the expert's coverage, read from the task's export
pytestmark = pytest.mark.worker

SAMPLED = {"protocol": "sampled"}
HOST = [1, 1, 0, 1, 0, 1, 1, 1]
MIRROR = [1, 0, 0, 1, 1, 1, 1, 1]


@pytest.fixture(scope="module")
def base() -> EvalReport:
    return evaluate("tabletop_push", "zero", n_envs=8, max_steps=2, backend="c", threads=1)


def _report(base, outcomes, scene, task, states, backend="c", created="2026-12-02T00:00:00"):
    r = variant(base, outcomes, scene=scene, task=task, backend=backend, created_at=created)
    r = with_steps(r, [10 + i for i in range(len(outcomes))])
    return dataclasses.replace(r, options={**SAMPLED, "sampled_states": states})


def test_rows_pair_each_mirror_report_with_its_latest_libero_report(base, tmp_path):
    reports = {
        "old.json": _report(base, [0] * 8, "libero", "libero_object/0", 8, created="2026-11-01"),
        "host.json": _report(base, HOST, "libero", "libero_object/0", 8),
        # 1,024 draws against LIBERO's 8: pairs on seeds 0-7, where the states are the same
        "warp.json": _report(base, MIRROR, "libero_mjx", "libero_object/0", 1024, "warp"),
        "c.json": _report(base, MIRROR, "libero_mjx", "libero_object/0", 8),
        "spatial_host.json": _report(base, HOST, "libero", "libero_spatial/0", 8),
        "spatial_c.json": _report(base, HOST, "libero_mjx", "libero_spatial/0", 8),
    }
    for name, r in reports.items():
        save_report(r, tmp_path / name)
    rows = rows_from_reports(sorted(tmp_path.glob("*.json")))
    assert [(r["task"], r["backend"]) for r in rows] == [
        ("libero_spatial/0", "c"),
        ("libero_object/0", "c"),
        ("libero_object/0", "warp"),
    ]
    ref = paired_comparison(np.array(HOST, bool), np.array(MIRROR, bool))
    for row in rows[1:]:
        assert row["seeds"] == 8 and row["agreement"] == 6 / 8
        assert (row["only_libero"], row["only_mirror"]) == (1, 1)
        assert row["mcnemar_p"] == pytest.approx(ref.p_value)
        assert row["both_succeeded"] == 5 and row["steps_median_difference"] == 0
    assert rows[0]["agreement"] == 1.0 and rows[0]["coverage"] == "covered"


def test_a_mirror_report_without_a_partner_is_one_line_exit_2(base, tmp_path, capsys):
    save_report(_report(base, HOST, "libero", "libero_object/0", 8), tmp_path / "host.json")
    standard = dataclasses.replace(
        _report(base, MIRROR, "libero_mjx", "libero_object/0", 8), options={}
    )
    save_report(standard, tmp_path / "mirror.json")  # the standard protocol: another state
    with pytest.raises(SystemExit) as exc:
        main(["--from-reports", str(tmp_path / "host.json"), str(tmp_path / "mirror.json")])
    err = capsys.readouterr().err
    assert exc.value.code == 2 and len(err.strip().splitlines()) == 1
    assert "no LIBERO report of task 'libero_object/0'" in err
    other = dataclasses.replace(  # the same protocol, another policy: not its pair either
        _report(base, MIRROR, "libero_mjx", "libero_object/0", 8), policy="mlp:/tmp/mlp"
    )
    save_report(other, tmp_path / "mirror.json")
    with pytest.raises(ConfigError, match="same task, policy and protocol"):
        rows_from_reports([tmp_path / "host.json", tmp_path / "mirror.json"])


def test_resume_runs_only_the_tasks_without_a_row(tmp_path, monkeypatch, capsys):
    """`--resume` keeps the rows `--out` holds and runs the tasks without one for the same
    seeds, backend and protocol (a row of other seeds stays, its task is run again)."""
    from openral_mjx.benchmarks.libero import agreement

    out = tmp_path / "rows.json"
    kept = {"task": "libero_object/0", "seeds": 200, "backend": "c", "protocol": "sampled"}
    other = {**kept, "task": "libero_object/1", "seeds": 50}  # other seeds: run again
    out.write_text(json.dumps([kept, other]))
    ran = []

    def row(task, seeds, backend, *args):
        ran.append(task)
        return {**kept, "task": task}, None, None

    monkeypatch.setattr(agreement, "agreement_row", row)
    monkeypatch.setattr(agreement, "format_table", lambda rows: "\n".join(r["task"] for r in rows))
    tasks = ["libero_object/0", "libero_object/1", "libero_object/2"]
    argv = ["--tasks", *tasks, "--protocol", "sampled", "--out", str(out), "--resume"]
    main(argv)
    assert ran == tasks[1:]
    assert [(r["task"], r["seeds"]) for r in json.loads(out.read_text())] == [
        ("libero_object/0", 200),
        ("libero_object/1", 50),
        ("libero_object/1", 200),
        ("libero_object/2", 200),
    ]
    assert "kept 1 rows" in capsys.readouterr().out
    with pytest.raises(SystemExit) as exc:  # nothing to resume from
        main(["--tasks", *tasks, "--resume"])
    assert exc.value.code == 2
