"""`python -m openral_mjx.compare A.json B.json`: does policy B succeed more (or less) than A?

Reports of the same scene and task that share seeds are compared pairwise on their common
seeds (seed s is the same initial state in both runs, so the two outcomes of a seed are a
matched pair; pairing removes the between-seed variation): exact McNemar test on the
discordant pairs and Newcombe's paired interval for rate_B - rate_A. Reports with no seed in
common (or with `--unpaired`) are compared as independent samples: two-proportion z test or
Fisher's exact test, Newcombe's hybrid-score interval. A mirror scene's report and its
original's (``libero_mjx`` and ``libero``) pair the same way: seed s is one initial state on
both, and the steps-to-success line says whether one reaches the goal sooner. Paired reports
also get the mean B - A of the steps to success (seeds where both succeed) and of the total
reward (every common seed), each with a t interval. Reports of another scene, task or schema
version are not comparable, and a report that fails validation (a wrong type, a missing field,
counts that do not add up) or the same file given twice is refused: one line on stderr, exit
code 2.

Two suite reports (``eval --suite``) are compared task by task: each task's paired difference
with Holm's correction over the tasks, and the suite-mean difference with a stratified interval.
Three or more reports of one scene and task are compared pairwise (Holm over the pairs), with
the set of policies not significantly worse than the best. ``--out`` writes the comparison as
JSON, ``--plots DIR`` a PNG (per-task differences, or ranked rates and the pairwise matrix).

Example: ``python -m openral_mjx.compare results/random.json results/scripted.json``.
"""

from __future__ import annotations

import dataclasses
import itertools
import os
from collections.abc import Sequence
from pathlib import Path
from typing import Annotated, Any

import numpy as np
import tyro

from openral_mjx.cli.common import guarded, parse
from openral_mjx.core.errors import ConfigError, unknown
from openral_mjx.core.files import check_writable, check_writable_dir, write_json_atomic
from openral_mjx.report import EvalReport, load_report
from openral_mjx.scenes import mirrored, seed_cycles, seed_options
from openral_mjx.stats import UNPAIRED_TESTS, check_confidence, compare_reports, format_comparison
from openral_mjx.stats.report_families import (
    SCHEMA,
    check_family,
    compare_many_reports,
    compare_suite_reports,
    format_many_comparison,
    format_suite_comparison,
    is_suite,
    many_json,
    suite_json,
)
from openral_mjx.viz import require_viz
from openral_mjx.viz.comparison_plots import write_comparison_plots


@dataclasses.dataclass
class CompareArgs:
    """Compare eval reports: the success-rate difference B - A, its interval, a p-value; two
    suites task by task; or k policies pairwise."""

    reports: Annotated[tuple[Path, ...], tyro.conf.Positional]
    """Reports: A (the baseline) and B; two suite reports; or three or more of one task."""
    confidence: float = 0.95
    """Confidence level of the interval for the difference (the test's alpha is 1 - it)."""
    unpaired: bool = False
    """Compare as independent samples even when the reports share seeds (two reports only)."""
    test: str = "auto"
    """Unpaired test: auto, two-proportion-z or fisher-exact (auto: Fisher if a count < 5)."""
    out: Path | None = None
    """Write the comparison as JSON here."""
    plots: Path | None = None
    """Write a PNG into this folder: per-task differences (suites) or ranked rates and the
    pairwise matrix (three or more reports)."""


def _labels(paths: Sequence[Path]) -> list[str]:
    """Short names for the reports: file names without `.json`, or the paths where two
    names collide."""
    names = [p.stem for p in paths]
    return names if len(set(names)) == len(names) else [str(p) for p in paths]


def _check(args: CompareArgs) -> None:
    """Everything that can be refused before a report is read."""
    check_confidence(args.confidence)
    if args.test not in UNPAIRED_TESTS:
        raise unknown("unpaired test", args.test, UNPAIRED_TESTS)
    if len(args.reports) < 2:
        got = ", ".join(repr(str(p)) for p in args.reports) or "none"
        raise ConfigError(f"compare needs two reports or more (A B [C ...]), got {got}")
    if args.out is not None:
        check_writable(args.out)
    if args.plots is not None:
        require_viz()
        check_writable_dir(args.plots, "--plots")


def _family(args: CompareArgs, reports: list[EvalReport], labels: list[str]):
    """The suite or k-policy comparison of `reports` (more than two, or two suites)."""
    if args.unpaired or args.test != "auto":
        raise ConfigError(
            "--unpaired and --test apply to two single-task reports; suites and three or more "
            "reports are compared paired by seed"
        )
    first = reports[0]
    check_family(reports, labels, [mirrored(first.scene, r.scene) for r in reports])
    if len(reports) == 2:
        sc = compare_suite_reports(reports[0], reports[1], (labels[0], labels[1]), args.confidence)
        return sc, format_suite_comparison(sc), suite_json(sc)
    mc = compare_many_reports(reports, labels, 1 - args.confidence)
    return mc, format_many_comparison(mc), many_json(mc)


def _plain(value: Any) -> Any:
    """`value` with numpy scalars as Python numbers (for JSON)."""
    if isinstance(value, dict):
        return {k: _plain(v) for k, v in value.items()}
    if isinstance(value, list | tuple):
        return [_plain(v) for v in value]
    return value.item() if isinstance(value, np.generic) else value


def run(args: CompareArgs) -> int:
    _check(args)
    reports = [load_report(p) for p in args.reports]
    for i, j in itertools.combinations(range(len(args.reports)), 2):
        p, q = args.reports[i], args.reports[j]
        if os.path.samefile(p, q):  # also through links and other spellings of a path
            raise ConfigError(
                f"reports {str(p)!r} and {str(q)!r} are the same file: compare different runs"
            )
    labels = _labels(args.reports)
    comparison = None
    if len(reports) == 2 and not any(is_suite(r) for r in reports):
        if args.plots is not None:
            raise ConfigError(
                "--plots draws two suite reports or three reports or more; two single-task "
                "reports have no plot (drop --plots)"
            )
        a, b = reports
        rc = compare_reports(
            a,
            b,
            args.confidence,
            args.unpaired,
            args.test,
            mirrored(a.scene, b.scene),
            seed_options(a.scene, b.scene),
            seed_cycles(a.scene, b.scene),
        )
        text = format_comparison(rc, a, b, (str(args.reports[0]), str(args.reports[1])))
        data = {"schema_version": SCHEMA, "kind": "pair", "a": labels[0], "b": labels[1]}
        data |= dataclasses.asdict(rc)
    else:
        comparison, text, data = _family(args, reports, labels)
    if args.out is not None:
        write_json_atomic(args.out, _plain(data))
    print(text)
    if args.out is not None:
        print(f"comparison: {args.out}")
    if comparison is not None and args.plots is not None:
        for path in write_comparison_plots(comparison, args.plots):
            print(f"plot: {path}")
    return 0


def main(argv: Sequence[str] | None = None) -> None:
    """The command: `argv` (default: the process's arguments) -> exit code."""
    prog = "python -m openral_mjx.compare"
    args = parse(lambda: tyro.cli(CompareArgs, prog=prog, args=argv), prog)
    raise SystemExit(guarded(lambda: run(args)))


if __name__ == "__main__":
    main()
