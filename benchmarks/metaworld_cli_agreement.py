"""MetaWorld against its mirror seed by seed, the way a user checks it: CLI commands per task.

    python benchmarks/metaworld_cli_agreement.py --suite mt50 --seeds 100 --out results/mw_cli

For each task T of the suite, MetaWorld's scripted expert on seeds 0..N-1: on MetaWorld's own
env through the host adapter (`--scene metaworld`) on its pinned MuJoCo and on the mirror's
(`--opt mujoco=ours`), on the mirror on `c` (`--scene metaworld_mjx`), then `compare` of each
MetaWorld report with the mirror's. One JSON line per task goes to OUT/agreement.jsonl (a task
already there is skipped, so an interrupted run resumes), and the markdown tables are printed
at the end. Reports stay in OUT.
"""

from __future__ import annotations

import argparse
import json
import subprocess
import sys
import time
from pathlib import Path
from typing import Any

from openral_mjx.scenes import scene_suite

ORACLES = {"pinned": [], "ours": ["--opt", "mujoco=ours"]}
LABELS = {"pinned": "its pinned MuJoCo", "ours": "the mirror's MuJoCo"}


def run(argv: list[str]) -> None:
    """`python -m ARGV` or raise with what it printed."""
    proc = subprocess.run([sys.executable, "-m", *argv], capture_output=True, text=True)
    if proc.returncode != 0:
        raise RuntimeError(f"{' '.join(argv)} failed:\n{proc.stdout[-2000:]}{proc.stderr[-2000:]}")


def pair(cmp: Path) -> dict[str, Any]:
    """The numbers of one `compare --out` file."""
    c = json.loads(cmp.read_text())
    p, steps = c["comparison"], c.get("steps_difference") or {}
    return {
        "seeds": c["common_seeds"],
        "metaworld": p["successes_a"],
        "mirror": p["successes_b"],
        "both": p["both"],
        "only_metaworld": p["only_a"],
        "only_mirror": p["only_b"],
        "neither": p["neither"],
        "agreement": (p["both"] + p["neither"]) / c["common_seeds"],
        "mcnemar_p": p["p_value"],
        "difference": p["difference"],
        "ci": [p["ci_low"], p["ci_high"]],
        "steps_median": c.get("steps_median_difference"),
        "steps_mean": steps.get("mean"),
    }


def _has_seeds(report: Path, seeds: int) -> bool:
    """Whether `report` exists, complete, for seeds 0..`seeds`-1."""
    if not report.exists():
        return False
    r = json.loads(report.read_text())
    return r["partial"] is None and r["seed"] == 0 and r["n_episodes"] == seeds


def task_row(task: str, seeds: int, out: Path, oracles: list[str]) -> dict[str, Any]:
    """MetaWorld on the `oracles`' MuJoCos, the mirror, and their comparisons for `task`."""
    # at most 100 envs at once (a MetaWorld env holds its own model: ~20 MB each in a worker)
    batch = ["--n-envs", str(min(seeds, 100)), "--n-episodes", str(seeds)]
    common = ["--task", task, "--policy", "metaworld-expert", *batch]
    common += ["--no-breakdown"]
    mirror = out / f"{task}_mirror.json"
    if not _has_seeds(mirror, seeds):  # a later oracle's run reuses an earlier run's mirror
        mirror_argv = ["openral_mjx.eval", "--scene", "metaworld_mjx", "--backend", "c"]
        run([*mirror_argv, *common, "--out", str(mirror)])
    row: dict[str, Any] = {"task": task, "seeds": seeds}
    for name in oracles:
        opts = ORACLES[name]
        host, cmp = out / f"{task}_{name}.json", out / f"{task}_{name}_compare.json"
        start = time.perf_counter()
        run(["openral_mjx.eval", "--scene", "metaworld", *common, *opts, "--out", str(host)])
        row[f"{name}_s"] = round(time.perf_counter() - start, 1)
        run(["openral_mjx.compare", str(host), str(mirror), "--out", str(cmp)])
        row[name] = pair(cmp)
    return row


def markdown(rows: list[dict[str, Any]], oracle: str) -> str:
    head = (
        "| task | seeds | MetaWorld | mirror | both / only MetaWorld / only mirror / neither "
        "| per-seed agreement | exact McNemar p | steps to success, median mirror - MetaWorld "
        "(mean) |\n|---|---|---|---|---|---|---|---|"
    )
    lines = [head]
    for row in rows:
        r = row[oracle]
        mean = "" if r["steps_mean"] is None else f" ({r['steps_mean']:+.2f})"
        median = "-" if r["steps_median"] is None else f"{r['steps_median']:+g}"
        counts = f"{r['both']} / {r['only_metaworld']} / {r['only_mirror']} / {r['neither']}"
        lines.append(
            f"| {row['task']} | {r['seeds']} | {r['metaworld']} | {r['mirror']} | {counts} | "
            f"{100 * r['agreement']:.1f}% | {r['mcnemar_p']:.2g} | {median}{mean} |"
        )
    return "\n".join(lines)


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--suite", default="mt50", help="a metaworld_mjx suite (default mt50)")
    parser.add_argument("--tasks", nargs="*", help="these tasks instead of the suite's")
    parser.add_argument("--seeds", type=int, default=100, help="seeds 0..N-1 per task")
    parser.add_argument("--out", type=Path, required=True, help="folder for reports and rows")
    parser.add_argument(
        "--oracles",
        nargs="+",
        choices=list(ORACLES),
        default=list(ORACLES),
        help="MetaWorld on its pinned MuJoCo, on the mirror's (ours), or both (default)",
    )
    args = parser.parse_args()
    args.out.mkdir(parents=True, exist_ok=True)
    rows_path = args.out / "agreement.jsonl"
    done: dict[str, dict[str, Any]] = {}  # a task's rows at these seeds, merged in order
    if rows_path.exists():
        for r in map(json.loads, rows_path.read_text().splitlines()):
            if r["seeds"] == args.seeds:
                done.setdefault(r["task"], {}).update(r)
    tasks = args.tasks or scene_suite("metaworld_mjx", args.suite)
    for i, task in enumerate(tasks, 1):
        if all(o in done.get(task, {}) for o in args.oracles):
            continue
        row = task_row(task, args.seeds, args.out, args.oracles)
        with rows_path.open("a") as f:
            f.write(json.dumps(row) + "\n")
        done.setdefault(task, {}).update(row)
        rates = ", ".join(f"{o} {100 * row[o]['agreement']:.1f}%" for o in args.oracles)
        print(f"[{i}/{len(tasks)}] {task}: per-seed agreement {rates}", flush=True)
    rows = [done[t] for t in tasks if t in done]
    for oracle in args.oracles:
        print(f"\nMetaWorld on {LABELS[oracle]}\n\n{markdown(rows, oracle)}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
