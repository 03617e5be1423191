"""`compare` with two suite reports (per-task table with Holm, stratified suite mean) and with
k >= 3 reports of one task (pairwise with Holm, the set not worse than the best): the printed
table and the JSON are `stats.families`' answers on the reports' paired outcomes (whose
statistics tests/stats/test_families.py checks by simulation), the plots are written, and
every mismatch is one line, exit 2, nothing written."""

from __future__ import annotations

import dataclasses
import json
from pathlib import Path

import numpy as np
import pytest
from report_variants import suite_variant, variant

from openral_mjx import compare as compare_cli
from openral_mjx.report import EvalReport, load_report, save_report
from openral_mjx.stats.families import compare_many, compare_suites

SAVED = Path(__file__).parent.parent / "benchmarks/2026-11-23-ci2core/rays/box_c_nodepth.json"
PNG = b"\x89PNG\r\n\x1a\n"


@pytest.fixture(scope="module")
def base() -> EvalReport:
    return load_report(SAVED)


def run(capsys, tmp_path: Path, reports: list[EvalReport], *flags: str):
    """Save `reports` as r0.json, r1.json, ... in `tmp_path/in` and run compare on them from
    `tmp_path/cwd`; returns (exit code, stdout, stderr, files written in cwd)."""
    folder, cwd = tmp_path / "in", tmp_path / "cwd"
    folder.mkdir(exist_ok=True)
    cwd.mkdir(exist_ok=True)
    paths = []
    for i, r in enumerate(reports):
        save_report(r, folder / f"r{i}.json")
        paths.append(str(folder / f"r{i}.json"))
    flags = tuple(f.replace("{cwd}", str(cwd)) for f in flags)
    with pytest.raises(SystemExit) as exc:
        compare_cli.main([*paths, *flags])
    out, err = capsys.readouterr()
    return exc.value.code, out, err, sorted(p.relative_to(cwd) for p in cwd.rglob("*"))


def outcomes(rng, n: int, p_a: float, p_b: float) -> tuple[np.ndarray, np.ndarray]:
    a = rng.random(n) < p_a
    b = np.where(rng.random(n) < 0.5, a, rng.random(n) < p_b)
    return a, b


TASKS = {"reach": (40, 0.9, 0.9), "push": (120, 0.3, 0.7), "pick": (60, 0.5, 0.45)}


def test_two_suites_task_table_and_stratified_mean(capsys, tmp_path, base):
    rng = np.random.default_rng(0)
    data = {t: outcomes(rng, n, pa, pb) for t, (n, pa, pb) in TASKS.items()}
    a = suite_variant(base, {t: v[0] for t, v in data.items()})
    b = suite_variant(base, {t: v[1] for t, v in data.items()}, policy="other")
    code, out, err, written = run(
        capsys, tmp_path, [a, b], "--out", "{cwd}/c.json", "--plots", "{cwd}/plots"
    )
    assert code == 0, err
    ref = compare_suites(data)
    lines = out.splitlines()
    for task, c, adj in zip(ref.tasks, ref.per_task, ref.adjusted, strict=True):
        row = next(x for x in lines if x.startswith(task + " "))
        assert f"{100 * c.difference:+6.1f}" in row and f"[{100 * c.ci_low:+6.1f}," in row
        assert f"{adj:.2g}" in row and row.endswith(" *") == (adj <= 0.05)
    assert (
        f"suite mean (tasks weighted equally): B - A = {100 * ref.mean_difference:+.1f} points, "
        f"95% CI [{100 * ref.ci_low:+.1f}, {100 * ref.ci_high:+.1f}]"
    ) in out
    # push's +40 points on 120 seeds is significant after Holm; reach's zero is not
    assert next(x for x in lines if x.startswith("push ")).endswith(" *")
    data_json = json.loads((tmp_path / "cwd/c.json").read_text())
    assert data_json["kind"] == "suite"
    assert [t["task"] for t in data_json["tasks"]] == list(TASKS)
    assert [t["p_holm"] for t in data_json["tasks"]] == pytest.approx(list(ref.adjusted))
    assert data_json["ci_low"] == pytest.approx(ref.ci_low)
    assert written == [Path("c.json"), Path("plots"), Path("plots/compare_suite.png")]
    assert (tmp_path / "cwd/plots/compare_suite.png").read_bytes().startswith(PNG)


def test_suites_pair_within_each_task_by_seed(capsys, tmp_path, base):
    """B's episodes of one task in another order, and one task run on fewer seeds by A: the
    pairs are the same seeds of the same task, the unpaired episodes counted in a note."""
    a_out = {"reach": [1, 0, 1, 1, 0, 0], "push": [0, 0, 1, 0, 1, 1]}
    b_out = {"reach": [1, 1, 1, 0, 0, 1], "push": [1, 0, 1, 1, 1, 1]}
    a = suite_variant(base, a_out)
    b = suite_variant(base, b_out, policy="other")
    order = [5, 3, 1, 0, 2, 4]  # shuffle B's push episodes: their seeds travel with them
    push = [e for e in b.episodes if e.metadata["task"] == "push"]
    b = dataclasses.replace(b, episodes=b.episodes[:6] + [push[i] for i in order])
    a = dataclasses.replace(a, episodes=a.episodes[:5] + a.episodes[6:])  # drop reach seed 5
    # the per-task rows and totals no longer say 6 and 12: keep the report valid
    rows = [dataclasses.replace(a.per_task[0], n_episodes=5, successes=3, success_rate=0.6)]
    a = dataclasses.replace(
        a, per_task=rows + a.per_task[1:], n_episodes=11, successes=6, success_rate=6 / 11
    )
    code, out, err, _ = run(capsys, tmp_path, [a, b], "--confidence", "0.9")
    assert code == 0, err
    ref = compare_suites(
        {
            "reach": (a_out["reach"][:5], b_out["reach"][:5]),
            "push": (a_out["push"], b_out["push"]),
        },
        0.9,
    )
    assert f"B - A = {100 * ref.mean_difference:+.1f} points, 90% CI" in out
    assert "note: episodes with no partner are left out: reach 0 of A, 1 of B" in out


def test_k_policies_pairwise_holm_and_not_worse_than_best(capsys, tmp_path, base):
    rng = np.random.default_rng(3)
    n = 300
    u = rng.random(n)
    rates = {"ckpt10k": 0.35, "ckpt20k": 0.6, "ckpt30k": 0.62}
    # half the seeds shared difficulty (one uniform for all three), half independent
    shared = rng.random(n) < 0.5
    data = {k: np.where(shared, u < p, rng.random(n) < p) for k, p in rates.items()}
    folder = tmp_path / "in"
    folder.mkdir()
    paths = []
    for name, ok in data.items():
        save_report(variant(base, ok), folder / f"{name}.json")
        paths.append(str(folder / f"{name}.json"))
    with pytest.raises(SystemExit) as exc:
        compare_cli.main([*paths, "--out", str(tmp_path / "k.json"), "--plots", str(tmp_path)])
    out, err = capsys.readouterr()
    assert exc.value.code == 0, err
    ref = compare_many(data)
    assert ref.best == "ckpt30k" and ref.not_worse == ("ckpt20k", "ckpt30k")
    assert out.startswith("3 policies on 300 common seeds, ranked:")
    for (a, b), c in ref.pairs.items():
        row = next(x for x in out.splitlines() if x.strip().startswith(f"{b} - {a}"))
        assert f"{100 * c.difference:+6.1f}" in row
        assert f"Holm p {ref.adjusted[(a, b)]:.2g}" in " ".join(row.split())
    assert (
        "not significantly worse than the best (ckpt30k) at the 5% family-wise level: "
        "ckpt20k, ckpt30k"
    ) in out
    saved = json.loads((tmp_path / "k.json").read_text())
    assert saved["kind"] == "policies" and saved["not_worse"] == list(ref.not_worse)
    assert {(p["a"], p["b"]): p["p_holm"] for p in saved["pairs"]} == pytest.approx(ref.adjusted)
    assert (tmp_path / "compare_policies.png").read_bytes().startswith(PNG)


def test_two_plain_reports_write_json_too(capsys, tmp_path, base):
    a, b = variant(base, [1, 0, 1, 0]), variant(base, [1, 1, 1, 0], policy="other")
    code, out, err, written = run(capsys, tmp_path, [a, b], "--out", "{cwd}/pair.json")
    assert code == 0, err and "paired on 4 common seeds" in out
    saved = json.loads((tmp_path / "cwd/pair.json").read_text())
    assert saved["kind"] == "pair" and saved["comparison"]["only_b"] == 1
    assert written == [Path("pair.json")]


def _suites(base, **b_fields):
    a = suite_variant(base, {"reach": [1, 0, 1], "push": [0, 1, 1]})
    b_out = b_fields.pop("outcomes", {"reach": [1, 1, 1], "push": [0, 0, 1]})
    return a, suite_variant(base, b_out, **b_fields)


@pytest.mark.parametrize(
    "case, flags, needle",
    [
        ("suite tasks differ", [], "different tasks: 'pick', 'push' in one only"),
        ("suite seeds differ", [], "task 'push' shares no seed: r0 ran seeds 0..2"),
        ("suite vs task", [], "task 'insert_tube_in_block' (r1) vs 'mt3' (r0)"),
        ("k scenes differ", [], "scene 'tabletop_push' (r2) vs 'so101_box' (r0)"),
        ("k seeds differ", [], "r2 shares no seed with r0 (seeds 10..12 vs 0..2)"),
        ("k with a suite", [], "r2 is a suite report (2 tasks)"),
        ("k unpaired", ["--unpaired"], "--unpaired and --test apply to two single-task"),
        ("one report", [], "compare needs two reports or more (A B [C ...]), got '"),
        ("plots of a pair", ["--plots", "{cwd}/p"], "two single-task reports have no plot"),
        ("out is a dir", ["--out", "{cwd}"], "is a directory"),
    ],
)
def test_mismatches_are_one_line_exit_2_nothing_written(
    capsys, tmp_path, base, case, flags, needle
):
    one = variant(base, [1, 0, 1])
    reports = {
        "suite tasks differ": lambda: _suites(base, outcomes={"reach": [1], "pick": [0]}),
        "suite seeds differ": lambda: (
            _suites(base)[0],
            dataclasses.replace(
                _suites(base)[1],
                episodes=[
                    dataclasses.replace(e, metadata={**e.metadata, "seed": 10 + i})
                    if e.metadata["task"] == "push"
                    else e
                    for i, e in enumerate(_suites(base)[1].episodes)
                ],
            ),
        ),
        "suite vs task": lambda: (_suites(base)[0], one),
        "k scenes differ": lambda: (one, one, dataclasses.replace(one, scene="tabletop_push")),
        "k seeds differ": lambda: (one, one, variant(base, [1, 0, 1], seeds=range(10, 13))),
        "k with a suite": lambda: (one, one, dataclasses.replace(_suites(base)[0], task=one.task)),
        "k unpaired": lambda: (one, one, one),
        "one report": lambda: (one,),
        "plots of a pair": lambda: (one, variant(base, [1, 1, 1])),
        "out is a dir": lambda: (one, one, one),
    }[case]()
    code, out, err, written = run(capsys, tmp_path, list(reports), *flags)
    assert code == 2 and out == ""
    lines = err.strip().splitlines()
    assert len(lines) == 1 and lines[0].startswith("error: ") and needle in lines[0], err
    assert written == []
