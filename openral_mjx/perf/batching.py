"""Continuous batching against fixed chunks, side by side in one process (`bench --batching`).

Per batch size N: the same policy over the same seeds 0.. with `chunks` and with `refill`,
each a full evaluation (`run_evaluation`); per run the wall time (compile excluded, reported
apart), episodes/s, simulated env-steps/s (what the batch stepped, finished envs waiting
included), live env-steps/s (steps of running episodes) and their ratio, the success rate;
then refill against chunks on the seeds both ran (paired: exact McNemar, Newcombe interval).

A chunked run does the same work whatever the outcomes (every chunk steps N envs for the
episode length), so its episodes/s over the first `chunk_episodes` seeds is that of any longer
run: `chunk_episodes` (a multiple of N) keeps the slow reference affordable at a million seeds.
"""

from __future__ import annotations

from collections.abc import Callable
from typing import Any

import numpy as np

from openral_mjx.core.errors import ConfigError
from openral_mjx.evaluation import run_evaluation
from openral_mjx.scenes import Scene
from openral_mjx.stats import paired_comparison


def _row(ev: Any, batching: str) -> dict[str, Any]:
    r, timing = ev.report, ev.timing
    simulated = timing.env_steps
    live = int(np.asarray(ev.arrays["steps"]).sum())
    return {
        "batching": batching,
        "n_episodes": r.n_episodes,
        "compile_s": r.compile_s,
        "run_s": r.run_s,
        "episodes_per_s": r.episodes_per_s,
        "env_steps_per_s": r.env_steps_per_s,
        "live_env_steps_per_s": r.live_env_steps_per_s,
        "simulated_env_steps": simulated,
        "live_env_steps": live,
        "live_share": live / simulated,
        "batch_steps": timing.batch_steps,
        "successes": r.successes,
        "success_rate": r.success_rate,
        "ci": [r.ci_low, r.ci_high],
    }


def compare_batching(
    scene: Scene,
    policy: str,
    sizes: tuple[int, ...],
    n_episodes: int,
    *,
    chunk_episodes: int | None = None,
    refill_every: int = 1,
    max_steps: int | None = None,
    log: Callable[[str], None] = print,
) -> list[dict[str, Any]]:
    """One row per batch size: both runners' figures and refill's speed-up and agreement."""
    chunk_episodes = chunk_episodes or n_episodes
    for n in sizes:
        if n < 1 or n_episodes < n or chunk_episodes % n or not n <= chunk_episodes <= n_episodes:
            raise ConfigError(
                f"batching bench needs n_episodes ({n_episodes}) >= N ({n}) and chunk_episodes "
                f"({chunk_episodes}) a multiple of N, at most n_episodes"
            )
    rows = []
    for n in sizes:
        kw = dict(n_envs=n, backend=scene.backend.name, max_steps=max_steps)
        with run_evaluation(
            scene, policy, n_episodes=chunk_episodes, batching="chunks", **kw
        ) as ev:
            chunks = _row(ev, "chunks")
            chunk_success = np.asarray(ev.arrays["success"])
        log(_line(n, chunks))
        with run_evaluation(
            scene, policy, n_episodes=n_episodes, batching="refill", refill_every=refill_every, **kw
        ) as ev:
            refill = _row(ev, "refill")
            c = paired_comparison(chunk_success, np.asarray(ev.arrays["success"])[:chunk_episodes])
        log(_line(n, refill))
        speedup = refill["episodes_per_s"] / chunks["episodes_per_s"]
        agreement = {
            "seeds": chunk_episodes,
            "difference": c.difference,
            "ci": [c.ci_low, c.ci_high],
            "p_value": c.p_value,
            "only_chunks": c.only_a,
            "only_refill": c.only_b,
        }
        log(
            f"N={n:,}: refill {speedup:.2f}x chunks' episodes/s; live "
            f"{100 * refill['live_share']:.1f}% of simulated steps (chunks "
            f"{100 * chunks['live_share']:.1f}%); paired on "
            f"{chunk_episodes:,} seeds {100 * c.difference:+.2f} pts [{100 * c.ci_low:+.2f}, "
            f"{100 * c.ci_high:+.2f}], McNemar p = {c.p_value:.3g}"
        )
        rows.append(
            {
                "n_envs": n,
                "chunks": chunks,
                "refill": refill,
                "speedup": speedup,
                "paired": agreement,
            }
        )
    return rows


def _line(n: int, row: dict[str, Any]) -> str:
    lo, hi = row["ci"]
    return (
        f"N={n:,} {row['batching']:6s}: {row['n_episodes']:,} episodes in {row['run_s']:.2f} s "
        f"(compile {row['compile_s']:.1f} s): {row['episodes_per_s']:,.0f} episodes/s, "
        f"{row['env_steps_per_s']:,.0f} env-steps/s simulated, {row['live_env_steps_per_s']:,.0f} "
        f"live ({100 * row['live_share']:.1f}%); success {100 * row['success_rate']:.2f}% "
        f"[{100 * lo:.2f}, {100 * hi:.2f}]"
    )
