"""Tanh-squashed diagonal Gaussian policy distribution.

A pre-squash sample `u ~ N(mean, std)` is mapped to the action `a = tanh(u)` in (-1, 1). By the
change of variables,

    log pi(a) = log N(u; mean, std) - sum_i log(1 - tanh(u_i)^2),

and `log(1 - tanh(u)^2) = 2 (log 2 - u - softplus(-2 u))` is the overflow-free form used here: it
stays finite for any `u`, whereas `log(1 - a^2)` is `-inf` once `a` rounds to +-1 in float32
(already for |u| > 9).

PPO stores the pre-squash sample `u` and evaluates `log_prob_raw(u)`, so it never inverts tanh.
`log_prob(a)` (for a given squashed action) clips `a` into the open interval first, so it is finite
at +-1 exactly and beyond. The Gaussian is distrax's `MultivariateNormalDiag`; the squashing is
ours rather than `distrax.Transformed(..., distrax.Tanh())`, whose inverse is infinite at the
bounds. `tests/test_agents_units.py` checks both against each other in the interior.
"""

from __future__ import annotations

import functools
import math

import jax
import jax.numpy as jnp


def tanh_log_det_jacobian(u: jax.Array) -> jax.Array:
    """log |d tanh(u) / du| = log(1 - tanh(u)^2), summed over the last axis, stable for any u."""
    return jnp.sum(2.0 * (math.log(2.0) - u - jax.nn.softplus(-2.0 * u)), axis=-1)


class TanhNormal:
    """Diagonal Gaussian in pre-squash space followed by tanh. Arrays broadcast over batch axes."""

    def __init__(self, mean: jax.Array, std: jax.Array):
        self.mean = mean
        self.std = std

    @functools.cached_property
    def base(self):
        """The pre-squash Gaussian; distrax (with TensorFlow Probability's JAX substrate, about a second to import) is
        imported on first use, which an evaluation acting by the mode never makes."""
        import distrax

        return distrax.MultivariateNormalDiag(self.mean, self.std)

    @classmethod
    def from_network_output(cls, output: jax.Array, min_std: float = 1e-3) -> "TanhNormal":
        """Splits a network output of size 2 * action_size into mean and softplus(raw) + min_std."""
        mean, raw_std = jnp.split(output, 2, axis=-1)
        return cls(mean, jax.nn.softplus(raw_std) + min_std)

    def sample_raw(self, key: jax.Array) -> jax.Array:
        """A pre-squash sample u (apply `jnp.tanh` for the action)."""
        return self.mean + self.std * jax.random.normal(key, self.mean.shape, self.mean.dtype)

    def sample(self, key: jax.Array) -> jax.Array:
        """A squashed action tanh(u), u ~ N(mean, std): the stochastic counterpart of `mode`."""
        return jnp.tanh(self.sample_raw(key))

    def normal_log_prob(self, u: jax.Array) -> jax.Array:
        """log N(u; mean, std), summed over the action dimensions."""
        return self.base.log_prob(u)

    def log_prob_raw(self, u: jax.Array) -> jax.Array:
        """log pi(tanh(u)) from the pre-squash value u: finite for every finite u."""
        return self.normal_log_prob(u) - tanh_log_det_jacobian(u)

    def log_prob(self, action: jax.Array, eps: float = 1e-6) -> jax.Array:
        """log pi(action) for a squashed action; values at or beyond +-1 are clipped to +-(1 - eps)."""
        a = jnp.clip(action, -1.0 + eps, 1.0 - eps)
        return self.log_prob_raw(jnp.arctanh(a))

    def sample_with_noise(self, noise: jax.Array) -> tuple[jax.Array, jax.Array, jax.Array]:
        """(action, pre-squash sample, log-prob) for standard-normal `noise` (reparameterised)."""
        u = self.mean + self.std * noise
        return jnp.tanh(u), u, self.log_prob_raw(u)

    def sample_and_log_prob(self, key: jax.Array) -> tuple[jax.Array, jax.Array, jax.Array]:
        """(action, pre-squash sample, log-prob), with the log-prob computed from u (no arctanh)."""
        u = self.sample_raw(key)
        return jnp.tanh(u), u, self.log_prob_raw(u)

    def entropy(self, key: jax.Array) -> jax.Array:
        """One-sample estimate of the entropy: H[N(mean, std)] + E[log |det J_tanh(u)|].

        The squashed distribution has no closed-form entropy; the estimate is unbiased and its
        gradient flows through the reparameterised sample.
        """
        return self.entropy_from_noise(jax.random.normal(key, self.mean.shape, self.mean.dtype))

    def entropy_from_noise(self, noise: jax.Array) -> jax.Array:
        """`entropy` with the standard-normal sample supplied by the caller."""
        return self.base.entropy() + tanh_log_det_jacobian(self.mean + self.std * noise)

    def mode(self) -> jax.Array:
        """The deterministic action used for evaluation: tanh(mean)."""
        return jnp.tanh(self.mean)
