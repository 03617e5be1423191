"""Held-out evaluation of `mlp` params through the runner, as `python -m openral_mjx.eval` does.

Seed ranges (episode seed s is `jax.random.PRNGKey(s)`; training episodes use neither):
* demonstrations for behaviour cloning: seeds from 0 (the eval CLI's default range);
* validation, for periodic evaluation and choosing the best checkpoint: `VALIDATION_SEEDS`;
* test, for the final before/after comparison, never used to choose anything: `TEST_SEEDS`.
"""

from __future__ import annotations

import dataclasses
from typing import Any

import numpy as np

from openral_mjx.policies.mlp import MlpConfig, mlp_policy
from openral_mjx.runner import make_runner, resolve_batching
from openral_mjx.scenes.base import Scene
from openral_mjx.stats import wilson_interval

VALIDATION_SEEDS = 1_000_000_000
TEST_SEEDS = 2_000_000_000


@dataclasses.dataclass(frozen=True)
class EvalResult:
    """Success over held-out seeds (deterministic policy), with a 95% Wilson interval."""

    n_episodes: int
    successes: int
    success_rate: float
    ci_low: float
    ci_high: float
    mean_return: float
    diverged: int
    run_s: float
    compile_s: float


class HeldOutEvaluator:
    """Evaluates params of one `mlp` architecture on fixed seeds, compiling once."""

    def __init__(
        self,
        scene: Scene,
        config: MlpConfig,
        *,
        n_episodes: int,
        n_envs: int,
        max_steps: int,
        first_seed: int = VALIDATION_SEEDS,
    ) -> None:
        self.seeds = np.arange(first_seed, first_seed + n_episodes, dtype=np.int64)
        n_envs = min(n_envs, n_episodes)
        self.runner = make_runner(
            scene,
            mlp_policy(config),
            n_envs=n_envs,
            max_steps=max_steps,
            batching=resolve_batching("auto", scene.backend.name, n_episodes, n_envs),
        )

    def __call__(self, params: Any) -> EvalResult:
        return self.run(params)[0]

    def run(self, params: Any) -> tuple[EvalResult, np.ndarray]:
        """The result and the per-seed successes (bool, in seed order), for paired tests."""
        arrays, timing = self.runner.run(params, self.seeds)
        n = len(self.seeds)
        success = np.asarray(arrays["success"], bool)
        k = int(success.sum())
        low, high = wilson_interval(k, n)
        result = EvalResult(
            n_episodes=n,
            successes=k,
            success_rate=k / n,
            ci_low=low,
            ci_high=high,
            mean_return=float(arrays["total_reward"].mean()),
            diverged=int(arrays["diverged"].sum()),
            run_s=timing.run_s,
            compile_s=timing.compile_s,
        )
        return result, success
