"""The runner's per-seed arrays turned into the report's `EpisodeResult`s."""

from __future__ import annotations

from collections.abc import Callable, Mapping
from typing import Any

import numpy as np

from openral_mjx.report import EpisodeResult
from openral_mjx.runner import FACTOR_PREFIX, INFO_PREFIX, RunTiming


def float32_values(values: np.ndarray) -> list[float]:
    """float32 values as the shortest decimals that read back to the same float32 (the JSON
    stays compact and loses nothing)."""
    return [float(str(v)) for v in np.asarray(values, np.float32)]


def episode_results(
    arrays: Mapping[str, Any],
    seeds: np.ndarray,
    timing: RunTiming,
    control_dt: float,
    metadata: Mapping[str, Any],
    *,
    policy_latency: bool = False,
    describe: Callable[[dict[str, Any]], dict[str, Any]] | None = None,
) -> list[EpisodeResult]:
    """Turn the runner's per-env arrays into `EpisodeResult`s.

    Latency: with `policy_latency`, the policy's own per-step latency as the runner
    accumulated it (mean and max over the episode's steps, steps over the control period);
    otherwise the batch's per-step time from chunk timings. `describe` turns a seed's
    `info/...` values into metadata entries (the scene's `describe_episode`).
    """
    budget_ms = 1000 * control_dt
    step_ms = timing.step_ms()
    per_chunk = timing.batch_steps is None
    max_ms = max(step_ms)
    factors = {
        k.removeprefix(FACTOR_PREFIX): float32_values(v)
        for k, v in arrays.items()
        if k.startswith(FACTOR_PREFIX)
    }
    info = {
        k.removeprefix(INFO_PREFIX): v.tolist()
        for k, v in arrays.items()
        if k.startswith(INFO_PREFIX)
    }
    if policy_latency:
        lat_sum = arrays["latency_sum_ms"].tolist()
        lat_max = arrays["latency_max_ms"].tolist()
        lat_over = arrays["latency_violations"].tolist()
    rewards = float32_values(arrays["total_reward"])
    steps = arrays["steps"].tolist()
    success = arrays["success"].tolist()
    diverged = arrays["diverged"].tolist()
    overflowed = arrays["overflowed"].tolist()
    first = arrays["first_success_step"].tolist()
    results = []
    for i, seed in enumerate(seeds.tolist()):
        if policy_latency:
            mean_ms = round(lat_sum[i] / max(steps[i], 1), 4)
            ep_max_ms, violations = round(lat_max[i], 4), lat_over[i]
        else:
            mean_ms = step_ms[i // timing.n_envs if per_chunk else 0]
            ep_max_ms, violations = max_ms, steps[i] if mean_ms > budget_ms else 0
        extra = {} if not info else (describe or dict)({k: v[i] for k, v in info.items()})
        results.append(
            EpisodeResult(
                success=success[i],
                steps=steps[i],
                total_reward=rewards[i],
                mean_step_latency_ms=mean_ms,
                max_step_latency_ms=ep_max_ms,
                latency_budget_ms=budget_ms,
                budget_violations=violations,
                metadata={
                    **metadata,
                    "seed": seed,
                    "diverged": diverged[i],
                    **({"overflowed": True} if overflowed[i] else {}),
                    "first_success_step": first[i],
                    "factors": {k: v[i] for k, v in factors.items()},
                    **extra,
                },
            )
        )
    return results
