"""Running mean / variance of observations (or value targets), kept in the learner state.

One set of statistics is shared by all environments and all devices: a batch's moments are
reduced over every axis but the feature axis, and across devices with `psum` (so the result is the
same as on one device holding the whole batch). Merging uses Chan et al.'s parallel update, exact
for any batch sizes. With `decay`, the weight of the new batch is floored at `1 - decay`, turning
the exact running average into an exponential one once enough data has been seen (used for value
targets, whose scale drifts as the policy improves).
"""

from __future__ import annotations

import jax
import jax.numpy as jnp
from flax import struct


@struct.dataclass
class RunningStats:
    count: jax.Array
    """Samples seen (float32; its relative precision suffices far beyond 1e9 samples)."""
    mean: jax.Array
    var: jax.Array


def init(size: int | tuple = ()) -> RunningStats:
    shape = (size,) if isinstance(size, int) else tuple(size)
    return RunningStats(jnp.zeros(()), jnp.zeros(shape), jnp.ones(shape))


def update(stats: RunningStats, batch: jax.Array, axis_name: str | None = None, decay: float | None = None) -> RunningStats:
    """Merges the moments of `batch` (feature axes last, as `stats.mean`) into `stats`."""
    feature_ndim = stats.mean.ndim
    axes = tuple(range(batch.ndim - feature_ndim))
    n = jnp.asarray(float(jnp.size(batch) // max(1, int(jnp.size(stats.mean)))))
    total = jnp.sum(batch, axis=axes)
    if axis_name is not None:
        n = jax.lax.psum(n, axis_name)
        total = jax.lax.psum(total, axis_name)
    batch_mean = total / n
    sq = jnp.sum(jnp.square(batch - batch_mean), axis=axes)
    if axis_name is not None:
        sq = jax.lax.psum(sq, axis_name)
    batch_var = sq / n

    w = n / (stats.count + n)
    if decay is not None:
        w = jnp.maximum(w, 1.0 - decay)
    delta = batch_mean - stats.mean
    mean = stats.mean + w * delta
    var = (1.0 - w) * stats.var + w * batch_var + w * (1.0 - w) * jnp.square(delta)
    return RunningStats(stats.count + n, mean, var)


def std(stats: RunningStats, eps: float = 1e-8) -> jax.Array:
    return jnp.sqrt(stats.var + eps)


def normalize(stats: RunningStats, x: jax.Array, clip: float | None = None) -> jax.Array:
    """(x - mean) / std, optionally clipped to [-clip, clip]. Identity-like before any update."""
    y = (x - stats.mean) / std(stats)
    return y if clip is None else jnp.clip(y, -clip, clip)


def denormalize(stats: RunningStats, y: jax.Array) -> jax.Array:
    return y * std(stats) + stats.mean
