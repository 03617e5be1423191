"""Paired comparison of two eval reports on the same seeds: exact McNemar test (scipy).

    python benchmarks/paired_mcnemar.py BEFORE.json AFTER.json [--alpha 0.01] [--out R.json]

Both reports come from `python -m openral_mjx.eval` on the same seeds (e.g. `--seed 2000000000
--n-episodes 4096`, the held-out test range of `openral_mjx.training.evaluation`). Each seed
is one pair of Bernoulli outcomes; only discordant pairs carry information about the
difference: under H0 (equal success probability) the after-only successes among the
discordant pairs are Binomial(b + c, 1/2). Prints both rates with Wilson 95% intervals, the
discordant counts and the two-sided exact p-value; writes them as JSON with `--out`.
"""

from __future__ import annotations

import argparse
import math
import sys
from pathlib import Path

from scipy.stats import binomtest

from openral_mjx.schema import load_report, write_json_atomic
from openral_mjx.stats import wilson_interval


def outcomes(path: Path) -> tuple[str, dict[int, bool]]:
    report = load_report(path)
    return report.policy, {e.metadata["seed"]: e.success for e in report.episodes}


def log10_p(k: int, n: int) -> float:
    """log10 of the two-sided exact p-value 2 P(X <= k), X ~ Binomial(n, 1/2), k <= n / 2,
    summed in log space: it stays finite where the p-value itself underflows."""
    terms = [
        math.lgamma(n + 1) - math.lgamma(j + 1) - math.lgamma(n - j + 1) - n * math.log(2)
        for j in range(k + 1)
    ]
    top = max(terms)
    log_tail = top + math.log(sum(math.exp(t - top) for t in terms))
    return min(0.0, (math.log(2) + log_tail) / math.log(10))


def compare(before: dict[int, bool], after: dict[int, bool]) -> dict:
    seeds = sorted(set(before) & set(after))
    if not seeds:
        raise SystemExit("error: the reports share no seeds")
    b = sum(1 for s in seeds if before[s] and not after[s])  # before-only successes
    c = sum(1 for s in seeds if after[s] and not before[s])  # after-only successes
    p = binomtest(c, b + c, 0.5).pvalue if b + c else 1.0
    out = {
        "n_common_seeds": len(seeds),
        "before_only": b,
        "after_only": c,
        "p_value": p,
        "log10_p_value": log10_p(min(b, c), b + c) if b + c else 0.0,
    }
    for name, runs in (("before", before), ("after", after)):
        k = sum(runs[s] for s in seeds)
        low, high = wilson_interval(k, len(seeds))
        out[name] = {"successes": k, "rate": k / len(seeds), "ci_low": low, "ci_high": high}
    return out


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("before", type=Path)
    parser.add_argument("after", type=Path)
    parser.add_argument("--alpha", type=float, default=0.01)
    parser.add_argument("--out", type=Path)
    args = parser.parse_args(argv)
    (name_a, a), (name_b, b) = outcomes(args.before), outcomes(args.after)
    r = compare(a, b)
    n = r["n_common_seeds"]
    for label, name in (("before", name_a), ("after", name_b)):
        x = r[label]
        print(
            f"{label:>6}: {name}  {x['successes']}/{n} = {100 * x['rate']:.1f}% "
            f"[{100 * x['ci_low']:.1f}, {100 * x['ci_high']:.1f}] (Wilson 95%)"
        )
    verdict = "significant" if r["p_value"] < args.alpha else "not significant"
    print(
        f"paired on {n} common seeds: before-only successes {r['before_only']}, after-only "
        f"{r['after_only']}; exact McNemar p = {r['p_value']:.3g} "
        f"(log10 p = {r['log10_p_value']:.1f}, two-sided): {verdict} at alpha = {args.alpha}"
    )
    if args.out:
        write_json_atomic(args.out, {**r, "before_policy": name_a, "after_policy": name_b})
    return 0


if __name__ == "__main__":
    sys.exit(main())
