"""The plan CLI: paired seeds for a difference (stated, measured or independence discordance)
and episodes for an interval, each answer the library's; every bad value -> one line, exit 2."""

import dataclasses
import json
from pathlib import Path

import numpy as np
import pytest
from report_variants import variant

from openral_mjx import compare as compare_cli
from openral_mjx import plan as plan_cli
from openral_mjx.evaluation.sequential import PairedRule
from openral_mjx.report import EvalReport, load_report, save_report
from openral_mjx.stats import (
    PairedDesign,
    Pilot,
    episodes_for_halfwidth,
    paired_comparison,
    plan_paired,
    unpaired_comparison,
)
from openral_mjx.stats.decide_planning import format_decide_plan, plan_decide
from openral_mjx.stats.report_families import SCHEMA as COMPARISON_SCHEMA

SAVED = Path(__file__).parent.parent / "benchmarks/2026-11-23-ci2core/rays/box_c_nodepth.json"


@pytest.fixture(scope="module")
def base() -> EvalReport:
    return load_report(SAVED)


def run_plan(capsys, *argv: str) -> tuple[int, str, str]:
    with pytest.raises(SystemExit) as exc:
        plan_cli.main(list(argv))
    out, err = capsys.readouterr()
    return exc.value.code, out, err


def test_compare_with_a_stated_discordance(capsys):
    code, out, err = run_plan(
        capsys, "compare", "--rate", "0.6", "--difference", "0.1", "--discordance", "0.2"
    )
    plan = plan_paired(PairedDesign(0.6, 0.1, 0.2))
    assert code == 0 and err == ""
    first = out.splitlines()[0]
    assert first.startswith(f"{plan.seeds} paired seeds detect B - A = +10.0 points with ")
    assert f"{100 * plan.power:.1f}% power (target 80%; exact McNemar test" in first
    assert "only A succeeds on 5.0% of seeds, only B on 15.0%" in out
    assert "discordance: as stated (--discordance)" in out


def test_compare_without_a_discordance_assumes_independence(capsys):
    code, out, _ = run_plan(
        capsys, "compare", "--rate", "0.3", "--difference", "-0.15", "--alpha", "0.01"
    )
    plan = plan_paired(PairedDesign.independent(0.3, -0.15, alpha=0.01))
    assert code == 0
    assert out.startswith(f"{plan.seeds} paired seeds detect B - A = -15.0 points")
    assert "two-sided alpha 0.01" in out and "if outcomes were independent" in out


def test_compare_not_reached_within_max_seeds(capsys):
    argv = ["compare", "--rate", "0.6", "--difference", "0.1", "--discordance", "0.2"]
    code, out, _ = run_plan(capsys, *argv, "--max-seeds", "50")
    assert code == 0 and out.startswith("not reached within 50 paired seeds")


def _pilot_reports(base, tmp_path, a, b, seeds_b=None):
    ra = variant(base, a)
    rb = variant(base, b, seeds=seeds_b, policy="other")
    save_report(ra, tmp_path / "a.json")
    save_report(rb, tmp_path / "b.json")
    return str(tmp_path / "a.json"), str(tmp_path / "b.json")


def test_compare_from_reports_measures_the_discordance(capsys, tmp_path, base):
    rng = np.random.default_rng(5)
    a = rng.random(200) < 0.5
    b = np.where(rng.random(200) < 0.3, ~a, a)
    pa, pb = _pilot_reports(base, tmp_path, a, b)
    code, out, err = run_plan(capsys, "compare", "--difference", "0.1", "--from", pa, pb)
    assert code == 0, err
    pilot = Pilot.from_comparison(paired_comparison(a, b))
    plan = plan_paired(pilot.design(0.1))
    upper = plan_paired(pilot.design(0.1, upper=True))
    assert out.startswith(f"{plan.seeds} paired seeds")
    assert f"A {100 * a.mean():.1f}%" in out  # A's rate defaults to the report's
    assert f"measured on 200 common seeds of {pa} and {pb}" in out
    assert out.splitlines()[-1].endswith(
        f"upper end ({100 * upper.design.discordance:.1f}%): {upper.seeds} seeds"
    )
    # at A's rate 0.76 (B 0.86) no discordance above 0.38 is possible: the upper end is clipped
    code, out, _ = run_plan(
        capsys, "compare", "--difference", "0.1", "--rate", "0.76", "--from", pa, pb
    )
    clipped = pilot.design(0.1, rate=0.76, upper=True)
    assert code == 0 and pilot.discordance <= clipped.discordance < pilot.interval[1]
    assert (
        f"upper end ({100 * pilot.interval[1]:.1f}%, at most {100 * clipped.discordance:.1f}% "
        "at these rates)"
    ) in out


@pytest.mark.parametrize(
    "argv, needle",
    [
        (["--rate", "1.2", "--difference", "0.1"], "rate must lie in [0, 1], got 1.2"),
        (["--rate", "0.6", "--difference", "0.5"], "valid [-0.6, 0.4] except 0"),
        (["--rate", "0.6", "--difference", "0"], "difference must be non-zero"),
        (["--rate", "0.6", "--difference", "0.1", "--discordance", "0.05"], "[0.1, 0.7]"),
        (["--rate", "0.6", "--difference", "0.1", "--discordance", "1.2"], "got 1.2"),
        (["--rate", "0.6", "--difference", "0.1", "--alpha", "1.5"], "alpha must lie in (0, 1)"),
        (["--rate", "0.6", "--difference", "0.1", "--power", "0"], "power must lie in (0, 1)"),
        (["--rate", "0.6", "--difference", "0.1", "--max-seeds", "0"], "--max-seeds must lie in"),
        (["--rate", "nan", "--difference", "0.1"], "--rate must be a finite number, got nan"),
        (["--difference", "0.1"], "give --rate"),
        (["--rate", "0.6"], "--difference"),
    ],
)
def test_compare_bad_values_are_one_line_exit_2(capsys, argv, needle):
    code, out, err = run_plan(capsys, "compare", *argv)
    assert code == 2 and out == ""
    lines = err.strip().splitlines()
    assert len(lines) == 1 and lines[0].startswith("error: ") and needle in lines[0], err


def test_compare_from_bad_reports(capsys, tmp_path, base):
    a = [1, 0, 1, 0, 1, 1, 0, 0, 1, 0]
    pa, pb = _pilot_reports(base, tmp_path, a, a[::-1], seeds_b=range(10, 20))
    cases = [
        (["--from", pa, pa], "same file twice"),
        (["--from", pa, pb], "the reports share no seeds"),
        (["--from", pa, pb, "--discordance", "0.2"], "give --discordance or --from, not both"),
        (["--from", pa, str(tmp_path / "nope.json")], "nope.json"),
    ]
    other = dataclasses.replace(variant(base, a), task="other")
    save_report(other, tmp_path / "other.json")
    cases.append((["--from", pa, str(tmp_path / "other.json")], "not comparable: task"))
    (tmp_path / "same").mkdir()
    _, pb_same = _pilot_reports(base, tmp_path / "same", a, a)
    cases.append((["--from", pa, pb_same, "--difference", "0.3"], "disagree on 0 of 10"))
    for argv, needle in cases:
        argv = argv if "--difference" in argv else [*argv, "--difference", "0.1"]
        code, _, err = run_plan(capsys, "compare", *argv)
        assert code == 2 and len(err.strip().splitlines()) == 1 and needle in err, (argv, err)


def test_interval(capsys):
    code, out, _ = run_plan(capsys, "interval", "--rate", "0.6", "--halfwidth", "0.03")
    assert code == 0
    n, worst = episodes_for_halfwidth(0.03, 0.6), episodes_for_halfwidth(0.03, 0.5)
    assert out.splitlines() == [
        f"{n:,} seeds give a 95% Wilson interval of half-width <= 3 points at an observed rate "
        "of 60.0%",
        f"at a rate of 50% (the widest, so enough at any rate): {worst:,} seeds",
    ]
    code, out, _ = run_plan(
        capsys,
        "interval",
        "--halfwidth",
        "0.05",
        "--method",
        "clopper-pearson",
        "--confidence",
        "0.9",
    )
    n = episodes_for_halfwidth(0.05, 0.5, 0.9, "clopper-pearson")
    assert code == 0
    assert out == (
        f"{n:,} seeds give a 90% Clopper-Pearson interval of half-width <= 5 points at an "
        "observed rate of 50.0%\n"
    )


@pytest.mark.parametrize(
    "argv, needle",
    [
        (["--halfwidth", "0.6"], "halfwidth must lie in (0, 0.5), got 0.6"),
        (["--halfwidth", "0.03", "--rate", "-0.1"], "rate must lie in [0, 1], got -0.1"),
        (["--halfwidth", "0.03", "--confidence", "95"], "confidence must lie in (0, 1)"),
        (["--halfwidth", "0.03", "--method", "wald"], "unknown interval method 'wald'"),
        (["--halfwidth", "inf"], "--halfwidth must be a finite number"),
    ],
)
def test_interval_bad_values_are_one_line_exit_2(capsys, argv, needle):
    code, out, err = run_plan(capsys, "interval", *argv)
    assert code == 2 and out == ""
    assert len(err.strip().splitlines()) == 1 and needle in err, err


def test_decide_prints_the_libraries_plan(capsys):
    """`plan decide` is `plan_decide` formatted: the cap, its power, the expected seeds under
    the effect and under none, and the fixed-size test's seeds."""
    argv = ["decide", "--difference", "0.2", "--discordance", "0.4", "--looks-every", "20"]
    code, out, err = run_plan(capsys, *argv)
    assert code == 0 and err == ""
    plan = plan_decide(0.2, 0.4, looks_every=20)
    assert plan.design is not None
    assert out == format_decide_plan(plan) + "\n"
    assert out.startswith(f"cap {plan.design.cap} seeds ({len(plan.design.looks)} looks of 20)")
    assert f"--n-envs 20 --n-episodes {plan.design.cap}" in out


def _decide_report(base: EvalReport, a: np.ndarray, b: np.ndarray, chunk: int) -> EvalReport:
    """B's report of `eval --compare-with A --decide` on these outcomes (looks every `chunk`
    seeds, cap: A's seeds), as the run writes it: B's episodes up to the deciding look."""
    rule = PairedRule(a, "a.json", "zero")
    for n in range(chunk, a.size + 1, chunk):
        if rule({"success": b[:n]}):
            break
    n = rule.looks[-1].n
    return dataclasses.replace(variant(base, b[:n], policy="other"), decision=rule.info())


def test_decide_from_a_decide_report_or_a_comparison(capsys, tmp_path, base):
    """--from reads the discordance (and A's rate) off an earlier paired run: a --decide
    report's last look, or compare's JSON of two reports; both give the plan at the
    discordance counted directly on the outcomes, and the cap at its interval's upper end."""
    rng = np.random.default_rng(3)
    a = rng.random(200) < 0.5
    b = np.where(rng.random(200) < 0.42, ~a, a)  # no real difference: runs to the cap
    report = _decide_report(base, a, b, 40)
    assert report.decision is not None and report.decision.decision == "inconclusive"
    save_report(report, tmp_path / "b_decide.json")
    pilot = Pilot(200, int((a & ~b).sum()), int((~a & b).sum()), int(a.sum()))
    plan = plan_decide(0.3, pilot.discordance, looks_every=20)
    upper = pilot.design(0.3, upper=True).discordance
    cautious = plan_decide(0.3, upper, looks_every=20)
    assert plan.design is not None and cautious.design is not None
    assert cautious.design.cap >= plan.design.cap
    argv = ["decide", "--difference", "0.3", "--looks-every", "20", "--from"]
    code, out, err = run_plan(capsys, *argv, str(tmp_path / "b_decide.json"))
    assert code == 0, err
    lo, hi = pilot.interval
    assert out.splitlines() == [
        *format_decide_plan(plan).splitlines(),
        f"discordance: measured on 200 paired seeds of {tmp_path / 'b_decide.json'} (only A "
        f"{pilot.only_a}, only B {pilot.only_b}; A {100 * a.mean():.1f}%): "
        f"{100 * pilot.discordance:.1f}%, 95% Wilson interval [{100 * lo:.1f}%, {100 * hi:.1f}%]",
        f"at the interval's upper end ({100 * upper:.1f}%): cap {cautious.design.cap} seeds",
    ]
    # the same outcomes as two reports, compared with --out: the same plan
    pa, pb = _pilot_reports(base, tmp_path, a, b)
    with pytest.raises(SystemExit) as exc:
        compare_cli.main([pa, pb, "--out", str(tmp_path / "ab.json")])
    assert exc.value.code == 0
    capsys.readouterr()
    code, out2, err = run_plan(capsys, *argv, str(tmp_path / "ab.json"))
    assert code == 0, err
    assert out2 == out.replace(str(tmp_path / "b_decide.json"), str(tmp_path / "ab.json"))


def test_decide_from_bad_input(capsys, tmp_path, base):
    """A missing file, a report without paired outcomes, a comparison that is not of one
    pair on common seeds, too few discordant seeds, --from with --discordance, or neither:
    one line naming it, exit 2."""
    save_report(variant(base, [1, 0] * 20), tmp_path / "plain.json")
    rng = np.random.default_rng(4)
    a = rng.random(40) < 0.5
    save_report(_decide_report(base, a, a.copy(), 20), tmp_path / "agree.json")  # no discordance
    comparisons = {
        "suite.json": {"schema_version": COMPARISON_SCHEMA, "kind": "suite"},
        "unpaired.json": {
            "schema_version": COMPARISON_SCHEMA,
            "kind": "pair",
            "comparison": dataclasses.asdict(unpaired_comparison(5, 10, 7, 10)),
        },
        "old.json": {"schema_version": "openral_mjx.comparison/0", "kind": "pair"},
    }
    for name, data in comparisons.items():
        (tmp_path / name).write_text(json.dumps(data))
    cases = [
        (["--from", str(tmp_path / "nope.json")], "nope.json' does not exist"),
        (["--from", str(tmp_path / "plain.json")], "holds no paired outcomes"),
        (["--from", str(tmp_path / "suite.json")], "of kind 'suite', not 'pair'"),
        (["--from", str(tmp_path / "unpaired.json")], "unpaired.json' is unpaired"),
        (["--from", str(tmp_path / "old.json")], "has schema 'openral_mjx.comparison/0'"),
        (["--from", str(tmp_path / "agree.json")], "disagree on 0 of 40"),
        (["--from", str(tmp_path / "plain.json"), "--discordance", "0.3"], "not both"),
        ([], "give --discordance"),
    ]
    for argv, needle in cases:
        code, out, err = run_plan(capsys, "decide", "--difference", "0.1", *argv)
        lines = err.strip().splitlines()
        assert code == 2 and out == "" and len(lines) == 1, (argv, err)
        assert lines[0].startswith("error: ") and needle in lines[0], (argv, err)
