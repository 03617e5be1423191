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

Example: ``python -m openral_mjx.compare results/random.json results/scripted.json``.
"""

from __future__ import annotations

import dataclasses
import os
from collections.abc import Sequence
from pathlib import Path
from typing import Annotated

import tyro

from openral_mjx.cli.common import guarded, parse
from openral_mjx.core.errors import ConfigError, unknown
from openral_mjx.report import load_report
from openral_mjx.scenes import mirrored
from openral_mjx.stats import UNPAIRED_TESTS, check_confidence, compare_reports, format_comparison


@dataclasses.dataclass
class CompareArgs:
    """Compare two eval reports: the success-rate difference B - A, its interval, a p-value."""

    a: Annotated[Path, tyro.conf.Positional]
    """Report A (the baseline)."""
    b: Annotated[Path, tyro.conf.Positional]
    """Report B."""
    confidence: float = 0.95
    """Confidence level of the interval for the difference (the test's alpha is 1 - it)."""
    unpaired: bool = False
    """Compare as independent samples even when the reports share seeds."""
    test: str = "auto"
    """Unpaired test: auto, two-proportion-z or fisher-exact (auto: Fisher if a count < 5)."""


def run(args: CompareArgs) -> int:
    check_confidence(args.confidence)
    if args.test not in UNPAIRED_TESTS:
        raise unknown("unpaired test", args.test, UNPAIRED_TESTS)
    a, b = load_report(args.a), load_report(args.b)
    if os.path.samefile(args.a, args.b):  # also through links and other spellings of a path
        raise ConfigError(
            f"reports A and B are the same file ({str(args.a)!r}, {str(args.b)!r}): "
            "compare two runs"
        )
    rc = compare_reports(
        a, b, args.confidence, args.unpaired, args.test, mirrored(a.scene, b.scene)
    )
    print(format_comparison(rc, a, b, (str(args.a), str(args.b))))
    return 0


def main(argv: Sequence[str] | None = None) -> None:
    """The command: `argv` (default: the process's arguments) -> exit code."""
    prog = "python -m openral_mjx.compare"
    args = parse(lambda: tyro.cli(CompareArgs, prog=prog, args=argv), prog)
    raise SystemExit(guarded(lambda: run(args)))


if __name__ == "__main__":
    main()
