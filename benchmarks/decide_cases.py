"""Sequential paired comparison (`eval --compare-with A.json --decide`) against a fixed-size
test, on issue 40's three cases on tabletop_push (issue 40, "Measure").

One design serves all three cases, sized as a user would size it: `plan decide` for the
smallest effect worth detecting (`--difference` at `--discordance`, `--power`, looks every
`--n-envs` seeds) gives the cap, and the planning module gives the seeds the fixed-size exact
McNemar test needs for the same power at the same level. Per case, A runs on the cap's seeds
(a fixed run: `--decide` reads A's outcomes from its report), then B runs with `--decide`
against it and stops at the first look that decides:

* large: the scripted push expert (B) against the zero policy (A);
* small: the push expert at friction 0.5 (B) against 0.4 (A) (`--randomize friction=V`,
  cube and table, as `--sweep friction=...` sets it);
* none: the push expert against itself (same seeds: identical outcomes on a deterministic
  backend, so no seed is discordant; without `--margin` such a run goes to the cap).

    python benchmarks/decide_cases.py --backend warp --n-envs 256 --out results/decide_cases.json

Prints one line per case and writes (--out) the design and one row per case: the seeds B
used, the looks, the decision, B - A with its repeated interval (valid under the stopping
rule), the fixed-size test's seeds, and the wall time of A's and B's runs (each an
`eval` call in this process, compiling included; `compile_s`/`run_s` from the reports). The
reports themselves go to OUT's folder, `<out stem>_reports/`.
"""

from __future__ import annotations

import argparse
import contextlib
import datetime as dt
import io
import json
import time
from pathlib import Path

from openral_mjx import eval as eval_cli
from openral_mjx.core.files import write_json_atomic
from openral_mjx.evaluation import package_versions
from openral_mjx.report import EvalReport, load_report
from openral_mjx.stats.decide_planning import DecidePlan, plan_decide

# name: (A's policy and flags, B's policy and flags, what the case is)
CASES = {
    "large": (["--policy", "zero"], ["--policy", "scripted"], "scripted vs zero"),
    "small": (
        ["--policy", "scripted", "--randomize", "friction=0.4"],
        ["--policy", "scripted", "--randomize", "friction=0.5"],
        "push expert at friction 0.5 vs 0.4",
    ),
    "none": (["--policy", "scripted"], ["--policy", "scripted"], "push expert vs itself"),
}


def run_eval(argv: list[str]) -> tuple[EvalReport, float]:
    """`python -m openral_mjx.eval ARGV` in this process: its report (at ARGV's --out) and
    wall time. Its printout is kept back unless it fails."""
    out = Path(argv[argv.index("--out") + 1])
    printed = io.StringIO()
    start = time.perf_counter()
    code: object = 0
    with contextlib.redirect_stdout(printed):
        try:
            eval_cli.main(argv)
        except SystemExit as e:
            code = e.code
    wall = time.perf_counter() - start
    if code not in (0, None):
        raise SystemExit(f"eval {' '.join(argv)}: exit code {code}\n{printed.getvalue()}")
    return load_report(out), wall


def design_row(plan: DecidePlan) -> dict:
    d, e, z = plan.design, plan.effect, plan.null
    assert d is not None and e is not None and z is not None
    return {
        "difference": plan.difference,
        "discordance": plan.discordance,
        "power_target": plan.target,
        "looks_every": plan.looks_every,
        "cap": d.cap,
        "alpha": d.alpha,
        "margin": d.margin,
        "spending": d.spending,
        "power": e.better if plan.difference > 0 else e.worse,
        "expected_seeds_at_effect": e.expected_seeds,
        "expected_seeds_at_no_difference": z.expected_seeds,
        "fixed_seeds": plan.fixed_seeds,
        "fixed_level": d.alpha_q,
        "rule": d.describe(),
    }


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--backend", default="auto")
    ap.add_argument("--n-envs", type=int, default=256, help="seeds per look (eval's --n-envs)")
    ap.add_argument("--difference", type=float, default=0.02, help="effect the design sizes for")
    ap.add_argument("--discordance", type=float, default=0.13, help="discordance at that effect")
    ap.add_argument("--power", type=float, default=0.8)
    ap.add_argument("--alpha", type=float, default=0.05)
    ap.add_argument(
        "--margin",
        type=float,
        default=0.0,
        help="equivalence margin (0: none; with one, planning takes minutes on 2 cores)",
    )
    ap.add_argument("--spending", default="obrien-fleming")
    ap.add_argument("--cases", nargs="+", default=list(CASES), choices=list(CASES))
    ap.add_argument("--max-steps", type=int, default=None, help="episode length (scene's default)")
    ap.add_argument("--threads", type=int, default=None, help="c backend: MuJoCo threads")
    ap.add_argument("--out", type=Path, default=Path("results/decide_cases.json"))
    args = ap.parse_args()
    margin = args.margin or None

    start = time.perf_counter()
    plan = plan_decide(
        args.difference,
        args.discordance,
        args.power,
        args.n_envs,
        args.alpha,
        margin,
        args.spending,
    )
    if plan.design is None:
        raise SystemExit(f"no cap reaches the power within {plan.max_seeds:,} seeds")
    design = design_row(plan) | {"plan_s": time.perf_counter() - start}
    cap = plan.design.cap
    print(
        f"design: cap {cap:,} seeds, looks every {args.n_envs:,}, for B - A = "
        f"{100 * args.difference:+g} points at discordance {100 * args.discordance:g}% with "
        f"{100 * design['power']:.1f}% power; fixed-size exact McNemar test: "
        f"{plan.fixed_seeds} seeds at level {plan.design.alpha_q:.3g} ({design['plan_s']:.1f} s "
        "to plan)"
    )

    folder = args.out.with_name(f"{args.out.stem}_reports")
    folder.mkdir(parents=True, exist_ok=True)
    common = ["--scene", "tabletop_push", "--backend", args.backend, "--n-envs", str(args.n_envs)]
    common += ["--no-breakdown"]
    for flag, value in (("--max-steps", args.max_steps), ("--threads", args.threads)):
        if value is not None:
            common += [flag, str(value)]
    decide = ["--decide", "--alpha", str(args.alpha), "--spending", args.spending]
    decide += [] if margin is None else ["--margin", str(margin)]

    rows = []
    for name in args.cases:
        a_flags, b_flags, what = CASES[name]
        a_path, b_path = folder / f"{name}_a.json", folder / f"{name}_b.json"
        a, a_wall = run_eval([*common, *a_flags, "--n-episodes", str(cap), "--out", str(a_path)])
        b_argv = [*common, *b_flags, "--compare-with", str(a_path), *decide, "--out", str(b_path)]
        b, b_wall = run_eval(b_argv)
        d = b.decision
        assert d is not None
        last = d.looks[-1]
        row = {
            "case": name,
            "what": what,
            "seeds_used": b.n_episodes,
            "looks": len(d.looks),
            "cap": d.cap,
            "fixed_seeds": plan.fixed_seeds,
            "decision": d.decision,
            "difference": d.difference,
            "ci_low": d.ci_low,
            "ci_high": d.ci_high,
            "only_a": last.only_a,
            "only_b": last.only_b,
            "a_rate_over_cap": a.success_rate,
            "b_rate_over_used": b.success_rate,
            "a_wall_s": a_wall,
            "b_wall_s": b_wall,
            "a_compile_s": a.compile_s,
            "b_compile_s": b.compile_s,
            "a_run_s": a.run_s,
            "b_run_s": b.run_s,
            "device": b.device,
            "a_command": a.command,
            "b_command": b.command,
        }
        rows.append(row)
        print(
            f"{name:>5} ({what}): {d.decision} after {b.n_episodes:,} of {cap:,} seeds "
            f"({len(d.looks)} looks; fixed-size test: {plan.fixed_seeds}); B - A = "
            f"{100 * d.difference:+.1f} points, repeated CI [{100 * d.ci_low:+.1f}, "
            f"{100 * d.ci_high:+.1f}]; only A {last.only_a}, only B {last.only_b}; "
            f"A {a_wall:.1f} s ({a.success_rate:.1%} over {a.n_episodes:,}), "
            f"B {b_wall:.1f} s (compile {b.compile_s:.1f} s)"
        )

    result = {
        "benchmark": "decide_cases",
        "created_at": dt.datetime.now(dt.UTC).isoformat(timespec="seconds"),
        "backend": args.backend,
        "n_envs": args.n_envs,
        "max_steps": args.max_steps,
        "design": design,
        "cases": rows,
        "versions": package_versions(),
    }
    write_json_atomic(args.out, result)
    print(f"written: {args.out}")
    print(json.dumps(rows, indent=1))


if __name__ == "__main__":
    main()
