"""The batched episode runner: `vmap` over envs, a loop over control steps, one `jit`.

`episode` is the pure-JAX episode of a batch of seeds; `chunks` runs any number of seeds
through it in fixed-size batches (`EpisodeRunner`); `refill` runs them with continuous batching
(`RefillRunner`: a slot whose episode ended takes the next seed); `seeds.run_seeds` picks
either; `factors` computes each seed's episode factors; `trace` re-runs chosen seeds step by
step. Below them: `device_layout` (one program per device over a 1-D env mesh), `memory` (fit
the batch into device memory), `export_cache` and `compile_cache` (warm starts), and
`processes` (several processes as one `jax.distributed` job). The runner knows no particular
scene: it uses the `Scene` and `Policy` contracts only.
"""

from openral_mjx.runner.chunks import (
    FACTOR_PREFIX,
    INFO_PREFIX,
    MAX_ENVS,
    MAX_EPISODES,
    MAX_STEPS,
    EpisodeRunner,
    RunTiming,
    check_counts,
    check_seeds,
    outcome_arrays,
    seed_chunks,
)
from openral_mjx.runner.episode import (
    TRACES,
    EpisodeArrays,
    make_episode_fn,
    make_trace_fn,
    seed_keys,
)
from openral_mjx.runner.factors import make_factor_fn
from openral_mjx.runner.refill import (
    BATCHING,
    RefillRunner,
    check_batching,
    finished_prefix,
    resolve_batching,
)
from openral_mjx.runner.seeds import make_runner, run_seeds
from openral_mjx.runner.trace import trace_seeds

__all__ = [
    "BATCHING",
    "FACTOR_PREFIX",
    "INFO_PREFIX",
    "MAX_ENVS",
    "MAX_EPISODES",
    "MAX_STEPS",
    "TRACES",
    "EpisodeArrays",
    "EpisodeRunner",
    "RefillRunner",
    "RunTiming",
    "check_batching",
    "check_counts",
    "check_seeds",
    "finished_prefix",
    "make_episode_fn",
    "make_factor_fn",
    "make_runner",
    "make_trace_fn",
    "outcome_arrays",
    "resolve_batching",
    "run_seeds",
    "seed_chunks",
    "seed_keys",
    "trace_seeds",
]
