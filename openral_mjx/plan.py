"""`python -m openral_mjx.plan`: how many seeds to run before running them.

``plan compare``: paired seeds (both policies on the same seeds, as `compare` pairs them) to
detect a difference rate_B - rate_A of ``--difference`` at A's rate ``--rate`` with power
``--power``, by the exact McNemar test at two-sided level ``--alpha``, which is the test
`compare` runs; its power is computed exactly. It depends on the discordance, the share of
seeds on which exactly one policy succeeds: stated (``--discordance``), measured on the common
seeds of two earlier reports (``--from A.json B.json``), or, with neither, what independent
outcomes would give (the output says which). ``plan interval``: episodes for a
``--halfwidth`` interval of one policy's success rate at about ``--rate``. ``plan decide``: the
cap (``--n-episodes``) of ``eval --decide``'s sequential design, looking every
``--looks-every`` seeds (its ``--n-envs``), that decides a ``--difference`` at ``--discordance``
with ``--power``, computed with the design's own exact boundaries; and the seeds it expects to
use at that difference and at none. Its discordance is stated, or measured by an earlier paired
run (``--from``: an ``eval --compare-with A.json --decide`` report, over the seeds it ran, or a
``compare A.json B.json --out C.json`` comparison, over their common seeds); then the cap at
the upper end of the discordance's interval is given too.

A value out of its range (a rate outside [0, 1], B's rate ``rate + difference`` outside it, a
discordance the rates cannot produce, alpha or power outside (0, 1)) is one line on stderr
naming it and the valid range, exit code 2.

Example: ``python -m openral_mjx.plan compare --rate 0.6 --difference 0.1 --discordance 0.2``,
``python -m openral_mjx.plan decide --difference 0.05 --discordance 0.2 --looks-every 256``.
"""

from __future__ import annotations

import dataclasses
import json
import os
from collections.abc import Sequence
from pathlib import Path
from typing import Annotated

import tyro

from openral_mjx.cli.common import guarded, parse
from openral_mjx.core.errors import ConfigError, unknown
from openral_mjx.report import load_report
from openral_mjx.stats import (
    INTERVAL_METHODS,
    PLAN_CAP,
    Comparison,
    PairedDesign,
    Pilot,
    check_confidence,
    compare_reports,
    format_interval_plan,
    format_paired_plan,
    plan_paired,
)
from openral_mjx.stats.decide_planning import format_decide_plan, plan_decide
from openral_mjx.stats.report_families import SCHEMA as COMPARISON_SCHEMA

MAX_SEEDS = PLAN_CAP  # the search's tables grow with it: ~15 s near 10^6 on 2 cores


@dataclasses.dataclass
class CompareArgs:
    """Paired seeds to detect a difference B - A with the exact McNemar test (as compare)."""

    difference: float
    """rate_B - rate_A to detect (0.1: ten points better; negative: worse)."""
    rate: float | None = None
    """A's success rate, about (required unless --from; then A's rate in those reports)."""
    discordance: float | None = None
    """Share of seeds on which exactly one policy succeeds (default: as if independent)."""
    from_: Annotated[tuple[Path, Path] | None, tyro.conf.arg(name="from")] = None
    """Two earlier reports (A B) whose common seeds measure the discordance."""
    alpha: float = 0.05
    """Two-sided level of the test."""
    power: float = 0.8
    """Power wanted: the probability of detecting the difference if it is real."""
    max_seeds: int = PLAN_CAP
    """The most seeds the search considers (at most 1,000,000)."""


@dataclasses.dataclass
class IntervalArgs:
    """Episodes for a success-rate interval of a given half-width."""

    halfwidth: float
    """Half-width wanted, as a fraction (0.03: +-3 points)."""
    rate: float = 0.5
    """The success rate expected, about (0.5, the default, is the worst case)."""
    confidence: float = 0.95
    """Confidence level of the interval."""
    method: str = "wilson"
    """Interval: wilson or clopper-pearson."""


@dataclasses.dataclass
class DecideArgs:
    """The cap of eval --decide (its --n-episodes) for a target power, and its expected seeds."""

    difference: float
    """rate_B - rate_A to decide (0.05: five points better; negative: worse)."""
    discordance: float | None = None
    """Share of seeds on which exactly one policy succeeds (at least |difference|); or --from."""
    from_: Annotated[Path | None, tyro.conf.arg(name="from")] = None
    """An earlier paired run that measures the discordance: an eval --compare-with A.json
    --decide report, or a comparison written by compare A.json B.json --out."""
    power: float = 0.8
    """Power wanted: the probability of deciding B better (or worse) if the difference is real."""
    looks_every: int = 256
    """Seeds between looks: eval --decide looks after every --n-envs seeds."""
    alpha: float = 0.05
    """eval --decide's --alpha (its test of no difference spends 0.9 of it)."""
    spending: str = "obrien-fleming"
    """eval --decide's --spending: obrien-fleming or pocock."""
    margin: float | None = None
    """eval --decide's --margin, if it will be given (slower to plan: seconds more)."""
    max_seeds: int = PLAN_CAP
    """The largest cap the search considers (at most 1,000,000)."""


def _pilot(paths: tuple[Path, Path]) -> Pilot:
    # imported here: the scene registry loads MJX (seconds), which only --from needs
    from openral_mjx.scenes import mirrored, seed_cycles, seed_options

    a, b = (load_report(p) for p in paths)
    if os.path.samefile(*paths):
        raise ConfigError(
            f"--from names the same file twice ({str(paths[0])!r}, {str(paths[1])!r}): give "
            "two runs"
        )
    same = seed_options(a.scene, b.scene)
    cycles = seed_cycles(a.scene, b.scene)
    rc = compare_reports(
        a, b, mirrored=mirrored(a.scene, b.scene), seed_options=same, seed_cycles=cycles
    )
    return Pilot.from_comparison(rc.comparison)


def _paired_pilot(path: Path) -> Pilot:
    """The discordance measured by the earlier paired run at `path`: a comparison of two
    reports (`compare --out`, over their common seeds) or an `eval --decide` report (over
    the seeds it ran); `ConfigError` naming the file for anything else."""
    label = str(path)
    if path.is_file():
        try:
            data = json.loads(path.read_text())
        except (OSError, UnicodeDecodeError, json.JSONDecodeError):
            data = None  # load_report says what is wrong with it
        if isinstance(data, dict) and str(data.get("schema_version", "")).startswith(
            COMPARISON_SCHEMA.partition("/")[0] + "/"
        ):
            return _comparison_pilot(data, label)
    return Pilot.from_decision(load_report(path), label)


def _comparison_pilot(data: dict, label: str) -> Pilot:
    """`Pilot` of a two-report comparison as `compare --out` writes it."""
    version, kind = data.get("schema_version"), data.get("kind")
    if version != COMPARISON_SCHEMA:
        raise ConfigError(
            f"comparison {label!r} has schema {version!r}; this version reads {COMPARISON_SCHEMA!r}"
        )
    if kind != "pair":
        raise ConfigError(
            f"comparison {label!r} is of kind {kind!r}, not 'pair': --from needs one discordance, "
            "from a comparison of two single-task reports"
        )
    try:
        comparison = Comparison(**data["comparison"])
    except (KeyError, TypeError) as e:
        raise ConfigError(f"comparison {label!r} has no valid 'comparison' block ({e})") from None
    if not comparison.paired or comparison.only_a is None or comparison.only_b is None:
        raise ConfigError(
            f"comparison {label!r} is unpaired (the reports shared no seeds, or --unpaired): "
            "the discordance needs both policies on the same seeds"
        )
    return Pilot.from_comparison(comparison)


def run_compare(args: CompareArgs) -> int:
    if not 1 <= args.max_seeds <= MAX_SEEDS:
        raise ConfigError(f"--max-seeds must lie in [1, {MAX_SEEDS:,}], got {args.max_seeds}")
    if args.from_ is None:
        if args.rate is None:
            raise ConfigError("give --rate (A's success rate, about), or --from A.json B.json")
        if args.discordance is None:
            design = PairedDesign.independent(args.rate, args.difference, args.alpha)
        else:
            design = PairedDesign(args.rate, args.difference, args.discordance, args.alpha)
        plan = plan_paired(design, args.power, args.max_seeds)
        print(format_paired_plan(plan))
        return 0
    if args.discordance is not None:
        raise ConfigError("give --discordance or --from, not both")
    pilot = _pilot(args.from_)
    plan = plan_paired(
        pilot.design(args.difference, args.rate, args.alpha), args.power, args.max_seeds
    )
    where = f" of {args.from_[0]} and {args.from_[1]}"
    lines = [format_paired_plan(plan, pilot, where)]
    upper = pilot.design(args.difference, args.rate, args.alpha, upper=True)
    if upper.discordance > plan.design.discordance:
        cautious = plan_paired(upper, args.power, args.max_seeds)
        seeds = "more than the cap" if cautious.seeds is None else f"{cautious.seeds:,} seeds"
        end = f"{100 * upper.discordance:.1f}%"
        if upper.discordance < pilot.interval[1]:
            end = f"{100 * pilot.interval[1]:.1f}%, at most {end} at these rates"
        lines.append(f"at the interval's upper end ({end}): {seeds}")
    print("\n".join(lines))
    return 0


def run_interval(args: IntervalArgs) -> int:
    check_confidence(args.confidence)
    if args.method not in INTERVAL_METHODS:
        raise unknown("interval method", args.method, INTERVAL_METHODS)
    print(format_interval_plan(args.halfwidth, args.rate, args.confidence, args.method))
    return 0


def run_decide(args: DecideArgs) -> int:
    if not 1 <= args.max_seeds <= MAX_SEEDS:
        raise ConfigError(f"--max-seeds must lie in [1, {MAX_SEEDS:,}], got {args.max_seeds}")
    if args.from_ is not None and args.discordance is not None:
        raise ConfigError("give --discordance or --from, not both")
    if args.from_ is None and args.discordance is None:
        raise ConfigError(
            "give --discordance (the share of seeds on which exactly one policy succeeds), or "
            "--from REPORT.json (an earlier paired run that measures it)"
        )

    def plan(discordance: float):
        return plan_decide(
            args.difference,
            discordance,
            args.power,
            args.looks_every,
            args.alpha,
            args.margin,
            args.spending,
            args.max_seeds,
        )

    if args.from_ is None:
        assert args.discordance is not None
        print(format_decide_plan(plan(args.discordance)))
        return 0
    pilot = _paired_pilot(args.from_)
    # A's measured rate bounds the discordances possible at this difference (checked here)
    measured = pilot.design(args.difference, alpha=args.alpha)
    low, high = pilot.interval
    lines = [
        format_decide_plan(plan(measured.discordance)),
        f"discordance: measured on {pilot.seeds:,} paired seeds of {args.from_} (only A "
        f"{pilot.only_a}, only B {pilot.only_b}; A {100 * measured.rate_a:.1f}%): "
        f"{100 * pilot.discordance:.1f}%, {round(100 * pilot.confidence)}% Wilson interval "
        f"[{100 * low:.1f}%, {100 * high:.1f}%]",
    ]
    upper = pilot.design(args.difference, alpha=args.alpha, upper=True)
    if upper.discordance > measured.discordance:
        cautious = plan(upper.discordance)
        cap = (
            f"more than {args.max_seeds:,} seeds"
            if cautious.design is None
            else f"cap {cautious.design.cap:,} seeds"
        )
        end = f"{100 * upper.discordance:.1f}%"
        if upper.discordance < high:
            end = f"{100 * high:.1f}%, at most {end} at these rates"
        lines.append(f"at the interval's upper end ({end}): {cap}")
    print("\n".join(lines))
    return 0


def main(argv: Sequence[str] | None = None) -> None:
    """The command: `argv` (default: the process's arguments) -> exit code."""
    prog = "python -m openral_mjx.plan"
    commands = {"compare": CompareArgs, "interval": IntervalArgs, "decide": DecideArgs}
    args = parse(lambda: tyro.extras.subcommand_cli_from_dict(commands, prog=prog, args=argv), prog)
    run = {CompareArgs: run_compare, IntervalArgs: run_interval, DecideArgs: run_decide}[type(args)]
    raise SystemExit(guarded(lambda: run(args)))


if __name__ == "__main__":
    main()
