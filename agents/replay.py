"""The replay buffer of `agents.sac`, kept in device memory inside the learner state.

A circular array of shape (rows, num_envs, ...): row t holds every env's transition of one step. Its env axis is
split over devices like the environments. Sampling is stratified over envs (each env contributes
batch_size / num_envs samples at uniformly drawn rows, or each block of num_envs / batch_size envs one sample) with
random numbers keyed by global sample index, so a run on two devices reproduces the one-device run.

The functions read a SAC config's `num_envs`, `batch_size`, `n_step` and `discount`.
"""

from __future__ import annotations

import jax
import jax.numpy as jnp
from flax import struct

from agents import offpolicy
from agents.loop import Parallel, Transition, per_env_keys


@struct.dataclass
class Replay:
    data: dict
    """obs, action, reward, termination, next_obs (and truncation for n-step windows); leaves (rows, num_envs, ...)."""
    position: jax.Array
    """Next row to write (int32)."""
    rows: jax.Array
    """Rows filled so far, at most the capacity (int32)."""


def empty(rows: int, num_envs: int, observation_size: int, action_size: int, n_step: int) -> Replay:
    """A buffer of `rows` rows of zeros; n-step windows stop at time-outs too, so they keep the truncation flags."""
    z = lambda *shape: jnp.zeros((rows, num_envs) + shape)  # noqa: E731
    data = {"obs": z(observation_size), "action": z(action_size), "reward": z(), "termination": z(),
            "next_obs": z(observation_size)}
    if n_step > 1:
        data["truncation"] = z()
    return Replay(data=data, position=jnp.zeros((), jnp.int32), rows=jnp.zeros((), jnp.int32))


def insert(replay: Replay, batch: Transition, capacity: int) -> Replay:
    """The batch's steps written at the next rows (of `capacity`), overwriting the oldest."""
    steps = batch.reward.shape[0]
    rows = (replay.position + jnp.arange(steps)) % capacity
    new = {"obs": batch.obs, "action": batch.action, "reward": batch.reward,
           "termination": batch.termination, "next_obs": batch.next_obs, "truncation": batch.truncation}
    new = {k: new[k] for k in replay.data}
    data = jax.tree.map(lambda buf, x: buf.at[rows].set(x), replay.data, new)
    return Replay(data, (replay.position + steps) % capacity, jnp.minimum(replay.rows + steps, capacity))


def _draw(key, sample_ids, draw):
    """`draw(key)` for each sample with its key folded from the global sample id, shaped like `sample_ids`."""
    return jax.vmap(draw)(per_env_keys(key, sample_ids.reshape(-1))).reshape(sample_ids.shape)


def _take(x, group: int, rows, offset):
    """Buffer entries by block of `group` neighbouring envs: out[b] = x[rows[b], b * group + offset[b]].

    `x` (buffer rows, local envs, ...); `rows` (blocks, ...) and `offset` broadcastable to it. A gather batched
    over the block axis: with the env axis split over devices, each device reads only its own envs (plain indexing
    into the split axis makes XLA's partitioner gather the batch on every device and sum it across them)."""
    blocks = x.reshape((x.shape[0], x.shape[1] // group, group) + x.shape[2:])
    return jax.vmap(lambda xb, r, o: xb[r, o], in_axes=(1, 0, 0))(blocks, rows, jnp.broadcast_to(offset, rows.shape))


def _flat(x, axis: int):
    """`x` with its axes `axis` and `axis + 1` merged into one."""
    return x.reshape(x.shape[:axis] + (-1,) + x.shape[axis + 2:])


def sample(replay: Replay, key, par: Parallel, config, capacity: int):
    """This device's share of a stratified batch; returns (transitions, global sample ids).

    The local envs form blocks of `group` neighbours (1 when batch_size >= num_envs); each block gives
    `per_block` samples, in the order of their global ids, at rows drawn uniformly (and, in a block of
    several envs, from one env drawn uniformly). The transitions hold obs, action, reward (the n-step return),
    discount (gamma^n, 0 where the episode terminated in the window), next_obs, and cost: the discounted count of
    terminations in the window (the failure cost of `SACConfig.failure_budget`)."""
    c = config
    ids = par.env_ids()
    k_env, k_row = jax.random.split(key)
    if c.batch_size >= c.num_envs:
        group, per_block = 1, c.batch_size // c.num_envs
        sample_ids = ids[:, None] * per_block + jnp.arange(per_block)
        offset = jnp.zeros(sample_ids.shape, jnp.int32)
    else:
        group, per_block = c.num_envs // c.batch_size, 1
        sample_ids = (ids[0] // group + jnp.arange(par.local_envs // group))[:, None]
        offset = _draw(k_env, sample_ids, lambda k: jax.random.randint(k, (), 0, group))
    if c.n_step == 1:
        rows = _draw(k_row, sample_ids, lambda k: jax.random.randint(k, (), 0, replay.rows))
        mb = jax.tree.map(lambda x: _flat(_take(x, group, rows, offset), 0), replay.data)
        return ({**mb, "discount": c.discount * (1.0 - mb["termination"]), "cost": mb["termination"]},
                sample_ids.reshape(-1))
    return _sample_nstep(replay, group, sample_ids, offset, k_row, c, capacity), sample_ids.reshape(-1)


def _sample_nstep(replay: Replay, group: int, sample_ids, offset, key, c, capacity: int):
    """n-step transitions: a window of n consecutive rows per sample, its first row uniform over the rows whose
    window is fully written, summed by `offpolicy.nstep_targets`."""
    oldest = (replay.position - replay.rows) % capacity
    first = _draw(key, sample_ids, lambda k: jax.random.randint(k, (), 0, replay.rows - c.n_step + 1))
    rows = (oldest + first[:, None, :] + jnp.arange(c.n_step)[:, None]) % capacity  # (blocks, n, per_block)
    window = jax.tree.map(lambda x: _flat(jnp.moveaxis(_take(x, group, rows, offset[:, None, :]), 1, 0), 1),
                          replay.data)  # leaves (n, samples, ...)
    returns, discounts, offsets = offpolicy.nstep_targets(window["reward"], window["termination"],
                                                          window["truncation"], c.discount, c.n_step)
    costs, _, _ = offpolicy.nstep_targets(window["termination"], window["termination"], window["truncation"],
                                          c.discount, c.n_step)
    # Batched over samples like `_take`: no gather across devices.
    next_obs = jax.vmap(lambda obs, k: obs[k], in_axes=(1, 0))(window["next_obs"], offsets[0])
    return {"obs": window["obs"][0], "action": window["action"][0], "reward": returns[0],
            "discount": discounts[0], "next_obs": next_obs, "cost": costs[0]}
