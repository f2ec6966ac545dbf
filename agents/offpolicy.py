"""Pure building blocks of fast off-policy learning: a categorical (distributional)
critic and n-step returns.

The distributional critic follows Bellemare et al. 2017, "A Distributional Perspective on
Reinforcement Learning" (C51): the return distribution is a categorical distribution on a fixed,
evenly spaced support of `num_atoms` atoms in [v_min, v_max]; the target distribution of
r + discount * Z(s', a') is projected back onto that support (their Algorithm 1) and the critic is
trained by cross-entropy against it. FastTD3 / FastSAC use the same critic with n-step returns at
thousands of environments.

Every function is jit-able, takes jax.numpy arrays and works over any leading batch axes.
`nstep_targets` is the exception in that time is its axis 0 (arrays of one rollout in time order,
as `agents.loop.Transition` holds them); every axis after it is a batch axis.
"""

from __future__ import annotations

import jax
import jax.numpy as jnp


# ----------------------------------------------------------------------------------------------
# Categorical critic (Bellemare et al. 2017).


def categorical_support(v_min: float, v_max: float, num_atoms: int):
    """The fixed atoms z_i = v_min + i * (v_max - v_min) / (num_atoms - 1), i = 0 .. num_atoms - 1
    (Bellemare et al. 2017, section 4): shape (num_atoms,). `num_atoms` is static and at least 2."""
    if int(num_atoms) < 2:
        raise ValueError(f"num_atoms={num_atoms!r} is invalid: allowed is an integer >= 2.")
    return jnp.linspace(v_min, v_max, int(num_atoms))


def categorical_projection(next_probs, rewards, discounts, support):
    """Project the distribution of r + discount * Z' onto `support` (Bellemare et al. 2017, Algorithm 1).

    `next_probs` (..., K): the probabilities p_j of the bootstrap distribution Z' on `support`;
    `rewards`, `discounts` (...): per sample; `discounts` already includes gamma^n and
    (1 - termination), so a terminal transition (discount 0) puts all its mass around r;
    `support` (K,): evenly spaced atoms from `categorical_support`.

    Each shifted atom T z_j = r + discount * z_j is clipped to [v_min, v_max]; its fractional index
    b_j = (T z_j - v_min) / dz lies between the atoms l = floor(b_j) and u = l + 1, which receive
    p_j (u - b_j) and p_j (b_j - l). Taking u = l + 1 (not ceil(b_j)) and l at most K - 2 keeps
    the mass of a b_j exactly on an atom, where Algorithm 1's l == u gives both terms weight 0:
    it goes whole to that atom. Returns (..., K) probabilities summing to 1 (for `next_probs`
    that do); a constant target (no gradient is meant to flow through it).

    A scatter-add, O(batch * K) memory; the hat-function form sum_j p_j max(0, 1 - |b_j - i|)
    (Rowland et al. 2018, the projection Pi_C) is the same numbers but built a (batch, K, K) array
    and ran 10x slower on CPU (4,096 and 32,768 samples of 101 atoms). On a GPU the adds into one
    atom may be summed in any order (float rounding differs between runs in the last bits).
    """
    num_atoms = support.shape[-1]
    v_min, v_max = support[0], support[-1]
    delta = (v_max - v_min) / (num_atoms - 1)
    shifted = rewards[..., None] + discounts[..., None] * support  # (..., K): T z_j
    # Clipping b to [0, K - 1] is clipping T z_j to [v_min, v_max], and no rounding can leave the support.
    b = jnp.clip((shifted - v_min) / delta, 0.0, num_atoms - 1)
    lower = jnp.clip(jnp.floor(b), 0, num_atoms - 2)
    upper_weight = b - lower
    shape = jnp.broadcast_shapes(next_probs.shape, b.shape)
    probs = jnp.broadcast_to(next_probs, shape).reshape(-1, num_atoms)
    lower = jnp.broadcast_to(lower, shape).reshape(-1, num_atoms).astype(jnp.int32)
    upper_weight = jnp.broadcast_to(upper_weight, shape).reshape(-1, num_atoms)
    # One scatter per sample, batched: with the batch split over devices, each device scatters its own samples.
    project = lambda p, low, w: jnp.zeros_like(p).at[low].add(p * (1.0 - w)).at[low + 1].add(p * w)
    return jax.vmap(project)(probs, lower, upper_weight).reshape(shape)


def categorical_cross_entropy(logits, target_probs):
    """The critic loss per sample: -sum_i target_i log softmax(logits)_i (Bellemare et al. 2017,
    Algorithm 1's last line), over the last axis; `target_probs` is a constant (stop_gradient), so
    the gradient wrt `logits` is softmax(logits) - target. Shapes (..., K) -> (...)."""
    target = jax.lax.stop_gradient(target_probs)
    return -jnp.sum(target * jax.nn.log_softmax(logits, axis=-1), axis=-1)


def categorical_mean(values, support, *, is_logits: bool):
    """The expected value sum_i p_i z_i of a categorical distribution on `support` (K,) (Bellemare
    et al. 2017, eq. 1's Q(x, a) = sum_i z_i p_i(x, a)). `values` (..., K) are logits when
    `is_logits` (softmax over the last axis first), else probabilities. Returns (...)."""
    probs = jax.nn.softmax(values, axis=-1) if is_logits else values
    return jnp.sum(probs * support, axis=-1)


# ----------------------------------------------------------------------------------------------
# n-step returns (Sutton & Barto 2018, section 7.1; as in Rainbow, Hessel et al. 2018, eq. 2).


def _shift(x, k: int, fill):
    """x[t + k] along axis 0, `fill` where t + k is past the end."""
    if k == 0:
        return x
    pad = jnp.full((k,) + x.shape[1:], fill, x.dtype)
    return jnp.concatenate([x[k:], pad], axis=0)


def nstep_targets(rewards, terminations, truncations, discount, n: int):
    """n-step returns of one rollout for every start step t, time on axis 0: arrays (T, ...).

    The window of step t has m_t = min(n, steps up to and including the first done step from t,
    steps left in the array) steps; done = termination or truncation, so a window never crosses an
    episode boundary. Returns three (T, ...) arrays:

    - returns R_t = sum_{k < m_t} discount^k r_{t+k};
    - bootstrap discounts discount^{m_t} (1 - terminated within the window): 0 where the episode
      really ended (no bootstrap), discount^{m_t} at a truncation (bootstrap from that step's stored
      terminal next_obs) or at the end of the array (bootstrap from the last step's next_obs);
    - offsets m_t - 1 (int32): the bootstrap observation is next_obs[t + m_t - 1] (`gather_nstep`).

    The n-step target is then R_t + bootstrap_discount_t * V(next_obs[t + offset_t]) (Sutton &
    Barto 2018, eq. 7.1). With n = 1: (r_t, discount (1 - termination_t), 0). `n` is static (a loop
    of n shifted array operations at trace time); `discount` may be a traced scalar.
    """
    n = int(n)
    if n < 1:
        raise ValueError(f"n={n!r} is invalid: allowed is an integer >= 1.")
    rewards = jnp.asarray(rewards)
    dtype = rewards.dtype
    terminations = jnp.asarray(terminations, dtype)
    dones = jnp.maximum(terminations, jnp.asarray(truncations, dtype))
    returns = jnp.zeros_like(rewards)
    terminated = jnp.zeros_like(rewards)
    steps = jnp.zeros(rewards.shape, jnp.int32)
    # A window ends at a done step and at the array's last step.
    cuts = dones.at[-1].set(1.0)
    inside = jnp.ones_like(rewards)  # step t + k is in t's window
    for k in range(n):
        if k > 0:
            inside = inside * (1.0 - _shift(cuts, k - 1, 1.0))  # step t + k - 1 did not end it
        returns = returns + inside * discount**k * _shift(rewards, k, 0.0)
        terminated = terminated + inside * _shift(terminations, k, 0.0)
        steps = steps + inside.astype(jnp.int32)
    bootstrap = jnp.power(jnp.asarray(discount, dtype), steps) * (1.0 - terminated)
    return returns, bootstrap, steps - 1


def gather_nstep(next_obs, offsets):
    """next_obs[t + offsets[t, e], e] for every (t, e): the bootstrap observations of
    `nstep_targets`. `next_obs` (T, E, ...), `offsets` (T, E) int -> (T, E, ...)."""
    time = jnp.arange(offsets.shape[0])[:, None] + offsets
    envs = jnp.arange(offsets.shape[1])[None, :]
    return next_obs[time, envs]
