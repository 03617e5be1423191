"""Continuous batching against fixed chunks, side by side in one process (issue 18).

For one scene and backend: the scripted expert over the same seeds with `--batching chunks`
and with `refill` at several refill periods; per run the wall time, episodes/s, env-steps/s
(what the slots simulated, resets included), the share of simulated steps that belonged to a
live episode, and the success rate; then each refill run compared with the chunked one on
the same seeds (paired: exact McNemar, Newcombe interval).

    python benchmarks/refill.py --scene tabletop_push --backend warp --n-envs 4096 \
        --n-episodes 16384 --refill-every 1 4 16 --out results/refill_push_warp.json
"""

from __future__ import annotations

import argparse
import datetime as dt
import json
import sys
import time
from pathlib import Path

import numpy as np

from openral_mjx.core.files import write_json_atomic
from openral_mjx.evaluation import build_scene, package_versions, run_evaluation
from openral_mjx.evaluation.provenance import device_description
from openral_mjx.runner.compile_cache import enable_compilation_cache
from openral_mjx.stats import compare_reports


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--scene", default="tabletop_push")
    ap.add_argument("--backend", default="auto")
    ap.add_argument("--policy", default="scripted")
    ap.add_argument("--n-envs", type=int, default=4096)
    ap.add_argument("--n-episodes", type=int, default=16384)
    ap.add_argument("--refill-every", type=int, nargs="+", default=[1, 4, 16])
    ap.add_argument(
        "--repeats", type=int, default=2, help="timed runs per setting (after one warm-up)"
    )
    ap.add_argument("--out", type=Path, default=Path("results/refill.json"))
    args = ap.parse_args()
    enable_compilation_cache()
    scene = build_scene(args.scene, backend=args.backend, n_envs=args.n_envs)
    settings = [("chunks", 1)] + [("refill", k) for k in args.refill_every]
    rows, reports = [], {}
    for batching, every in settings:
        kw = dict(
            n_envs=args.n_envs,
            n_episodes=args.n_episodes,
            backend=scene.backend.name,
            batching=batching,
            refill_every=every,
        )
        t = time.perf_counter()
        with run_evaluation(scene, args.policy, **kw) as ev:  # compiles, then one timed run
            first_s = time.perf_counter() - t
            report = ev.report
        timed = []
        for _ in range(args.repeats):
            with run_evaluation(scene, args.policy, **kw) as ev:
                timed.append(ev.report.run_s)
        steps = np.array([e.steps for e in report.episodes])
        simulated = report.env_steps_per_s * report.run_s
        row = {
            "batching": batching,
            "refill_every": every if batching == "refill" else None,
            "first_call_s": first_s,
            "compile_s": report.compile_s,
            "run_s": float(np.median(timed)),
            "run_s_all": timed,
            "episodes_per_s": report.n_episodes / float(np.median(timed)),
            "env_steps_per_s": simulated / float(np.median(timed)),
            "simulated_env_steps": round(simulated),
            "live_share": float(steps.sum() / simulated),
            "mean_episode_steps": float(steps.mean()),
            "success_rate": report.success_rate,
            "ci": [report.ci_low, report.ci_high],
            "successes": report.successes,
        }
        rows.append(row)
        reports[(batching, every)] = report
        print(
            f"{batching:7s} every {every:3d}: {row['run_s']:7.2f} s  "
            f"{row['episodes_per_s']:10,.0f} episodes/s  {row['env_steps_per_s']:12,.0f} "
            f"env-steps/s  live {100 * row['live_share']:5.1f}%  success "
            f"{100 * report.success_rate:5.2f}% [{100 * report.ci_low:.2f}, "
            f"{100 * report.ci_high:.2f}]",
            flush=True,
        )
    base = reports[("chunks", 1)]
    chunk_s = rows[0]["run_s"]
    for row, (batching, every) in zip(rows, settings, strict=True):
        row["speedup_vs_chunks"] = chunk_s / row["run_s"]
        if batching == "refill":
            c = compare_reports(base, reports[(batching, every)]).comparison
            row["vs_chunks"] = {
                "difference": c.difference,
                "ci": [c.ci_low, c.ci_high],
                "p_value": c.p_value,
                "only_chunks": c.only_a,
                "only_refill": c.only_b,
            }
            print(
                f"refill every {every}: {row['speedup_vs_chunks']:.2f}x chunks' episodes/s; "
                f"paired difference {100 * c.difference:+.2f} pts [{100 * c.ci_low:+.2f}, "
                f"{100 * c.ci_high:+.2f}], McNemar p = {c.p_value:.3g} "
                f"({c.only_a} seeds only chunks, {c.only_b} only refill)",
                flush=True,
            )
    write_json_atomic(
        args.out,
        {
            "scene": args.scene,
            "backend": scene.backend.name,
            "device": device_description(scene),
            "policy": args.policy,
            "n_envs": args.n_envs,
            "n_episodes": args.n_episodes,
            "rows": rows,
            "versions": package_versions(),
            "created_at": dt.datetime.now(dt.UTC).isoformat(timespec="seconds"),
            "command": "python benchmarks/refill.py " + " ".join(sys.argv[1:]),
        },
    )
    print(f"results: {args.out}")
    print(
        json.dumps(
            {
                r["batching"] + str(r["refill_every"] or ""): round(r["speedup_vs_chunks"], 3)
                for r in rows
            }
        )
    )


if __name__ == "__main__":
    main()
