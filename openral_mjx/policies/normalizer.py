"""Observation normalisation: running mean and variance, carried with a learned policy's params.

Training updates the statistics from batches of observations; evaluation applies the frozen
statistics saved in the checkpoint, so a policy sees identically scaled inputs in both.
"""

from __future__ import annotations

import jax
import jax.numpy as jnp
from flax import struct


@struct.dataclass
class RunningStats:
    """Per-feature mean and (population) variance over `count` observations."""

    mean: jax.Array  # (d,) float32
    var: jax.Array  # (d,) float32
    count: jax.Array  # () float32


def init_stats(size: int) -> RunningStats:
    """No observations yet: the identity normalisation (mean 0, variance 1)."""
    return RunningStats(
        mean=jnp.zeros(size, jnp.float32),
        var=jnp.ones(size, jnp.float32),
        count=jnp.zeros((), jnp.float32),
    )


def update_stats(stats: RunningStats, batch: jax.Array) -> RunningStats:
    """Merge a batch `(..., d)` into the statistics (Chan et al.'s parallel update)."""
    x = batch.reshape(-1, batch.shape[-1]).astype(jnp.float32)
    n = jnp.float32(x.shape[0])
    batch_mean = jnp.mean(x, axis=0)
    batch_var = jnp.mean(jnp.square(x - batch_mean), axis=0)
    total = stats.count + n
    delta = batch_mean - stats.mean
    mean = stats.mean + delta * (n / total)
    m2 = stats.var * stats.count + batch_var * n + jnp.square(delta) * (stats.count * n / total)
    return RunningStats(mean=mean, var=m2 / total, count=total)


def normalize(stats: RunningStats, obs: jax.Array, std_min: float, clip: float) -> jax.Array:
    """`(obs - mean) / max(std, std_min)`, clipped to `[-clip, clip]`.

    `std_min` keeps near-constant features (a resting cube's height) from turning float noise
    into large inputs; the clip bounds what an unseen state can feed the network. The division
    is a product with the reciprocal: XLA's CPU code divides a batch by a shared vector with
    last-bit differences between batch sizes, products do not.
    """
    inv_std = 1.0 / jnp.maximum(jnp.sqrt(stats.var), std_min)
    return jnp.clip((obs - stats.mean) * inv_std, -clip, clip)
