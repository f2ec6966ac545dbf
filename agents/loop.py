"""The training loop shared by PPO and SAC: one compiled chunk of updates, vmapped over seeds and
split over devices.

A chunk runs `n` updates (`n` is a traced scalar, so chunks of any length share one compiled
program). Each update

1. steps the batched environment `learner.steps_per_update` times (every environment, in
   `lax.scan`), asking `learner.act` for actions and recording `Transition`s, and
2. hands the `(steps_per_update, local_envs)` transitions to `learner.update`.

A learner is any object with the interface `Learner` (`init`, `act`, `update`, `policy`,
`steps_per_update`, `env_axes`, and for checkpoints and exports `export_policy`, `policy_state`),
registered with its config class in `agents.registry`. Everything a learner needs about devices comes in `Parallel`.

Data parallelism: the environments are split evenly over the devices of a 1-D mesh named "dev";
parameters are replicated. Two ways, same results up to float summation order: `multi_device=
"gspmd"` (the default) runs the one-device program under `jit` with the state's env axes sharded
and lets XLA's partitioner insert the collectives; `"shard_map"` runs the chunk per device and the
learners average gradients and normaliser moments with `Parallel.pmean` / `psum` (XLA's GPU
compiler has crashed on that program for the MJX arms). Random numbers are drawn per
*global* environment index, so a run on two devices reproduces the one-device run. With one device
no sharding is built and every collective is a no-op.

Seeds: every leaf of `TrainState` carries a leading seed axis and the chunk is `jax.vmap`ped over it.
"""

from __future__ import annotations

import dataclasses
import functools
from typing import Any, NamedTuple, Protocol

import jax
import jax.numpy as jnp
from flax import struct
from jax.sharding import Mesh, NamedSharding, PartitionSpec as P

from agents.ahead import Ahead, compiling

AXIS = "dev"
MULTI_DEVICE_MODES = ("shard_map", "gspmd")
"""How several devices can share the chunk (`Programs(multi_device=...)`, `TrainConfig.multi_device`)."""


class Transition(NamedTuple):
    """One environment step of every local environment (leading axes: time, env)."""

    obs: jax.Array
    action: jax.Array
    """The action sent to the environment, in [-1, 1]."""
    reward: jax.Array
    termination: jax.Array
    """1.0 where the episode really ended (no bootstrapping from `next_obs`)."""
    truncation: jax.Array
    """1.0 where the time limit ended the episode (bootstrap from `next_obs`)."""
    next_obs: jax.Array
    """Observation after the step; on a done step the *terminal* one (`info["final_obs"]`), not the
    first observation of the next episode."""
    extras: dict
    """Whatever `learner.act` returned besides the action (e.g. PPO's log-prob)."""

    @property
    def done(self) -> jax.Array:
        """Episode boundary (termination or truncation): advantage traces stop here."""
        return jnp.maximum(self.termination, self.truncation)


@dataclasses.dataclass(frozen=True)
class Parallel:
    """How the environments are split over devices, seen from inside the compiled chunk."""

    num_envs: int
    """Environments over all devices."""
    num_devices: int = 1
    axis_name: str | None = None
    """Mesh axis to reduce over; None with one device (collectives become identities)."""

    @property
    def local_envs(self) -> int:
        return self.num_envs // self.num_devices

    def env_ids(self) -> jax.Array:
        """Global indices of this device's environments."""
        offset = 0 if self.axis_name is None else jax.lax.axis_index(self.axis_name) * self.local_envs
        return offset + jnp.arange(self.local_envs)

    def pmean(self, tree):
        return tree if self.axis_name is None else jax.lax.pmean(tree, self.axis_name)

    def psum(self, tree):
        return tree if self.axis_name is None else jax.lax.psum(tree, self.axis_name)

    def mean_gradients(self, grads):
        """The global-batch gradient from this device's one (equal local batches: the mean).

        Explicit, because the chunk's `shard_map` runs with `check_vma=False` (MJX's solver is not
        written for varying-axis checks), so autodiff adds no implicit cross-device sums.
        """
        return self.pmean(grads)


def per_env_keys(key: jax.Array, env_ids: jax.Array) -> jax.Array:
    """One key per environment, a function of the global environment index only."""
    return jax.vmap(jax.random.fold_in, in_axes=(None, 0))(key, env_ids)


def env_random(key: jax.Array, par: "Parallel", shape: tuple, kind: str = "normal") -> jax.Array:
    """Random draws of `shape` per local environment, `(local_envs, *shape)`.

    Drawn for all global environments from one key and sliced to this device's contiguous block:
    every device count sees the same numbers per environment, and one batched draw replaces
    thousands of per-environment key derivations (measurably cheaper on a GPU every env step).
    """
    sample = jax.random.normal if kind == "normal" else functools.partial(jax.random.uniform, minval=-1.0, maxval=1.0)
    full = sample(key, (par.num_envs,) + tuple(shape))
    if par.axis_name is None:
        return full
    return jax.lax.dynamic_slice_in_dim(full, jax.lax.axis_index(par.axis_name) * par.local_envs, par.local_envs)


class Learner(Protocol):
    """What the loop needs from an algorithm (PPO and SAC implement it)."""

    steps_per_update: int
    """Environment steps taken by each environment between two updates."""

    transient_fields: tuple[str, ...]
    """Fields of the learner state that learner-only checkpoints (`TrainConfig.checkpoint_envs`
    False) leave out and a resume re-initialises (SAC: the replay buffer). Optional; default ()."""

    def init(self, key: jax.Array) -> Any:
        """The learner state (params, optimiser, normaliser, buffers) with *global* env axes."""

    def env_axes(self, state: Any) -> Any:
        """Per leaf of `state`, the axis that runs over environments (split over devices), or None."""

    def act(self, state: Any, obs: jax.Array, key: jax.Array, par: Parallel) -> tuple[jax.Array, dict]:
        """Exploration actions for the local envs and extras to store; draw per-env randomness
        with `env_random(key, par, ...)` so that it does not depend on the device count."""

    def update(self, state: Any, batch: Transition, key: jax.Array, par: Parallel) -> tuple[Any, dict]:
        """One update from `(steps_per_update, local_envs)` transitions; metrics are scalars
        already averaged over devices. Every key is checked for NaN and infinity (`agents.driver`)."""

    def policy(self, state: Any, obs: jax.Array) -> jax.Array:
        """Deterministic actions for evaluation."""

    def stochastic_policy(self, state: Any, obs: jax.Array, key: jax.Array) -> jax.Array:
        """Actions drawn from the policy's distribution (`eval.py --stochastic`)."""

    def export_policy(self, state: Any) -> tuple[Any, Any]:
        """(policy parameters, observation statistics): what `policy` reads (`agents.export` saves it)."""

    def policy_state(self, policy_params: Any, obs_stats: Any) -> Any:
        """A learner state holding only what `policy` reads; the inverse of `export_policy`."""

    def progress_note(self, updates_done: int) -> str | None:
        """A remark for a run stopped after `updates_done` updates (e.g. a schedule not at its end), or None."""


@struct.dataclass
class TrainState:
    """Everything a run needs to continue exactly; this is what a checkpoint stores."""

    learner: Any
    env_state: Any
    key: jax.Array
    episode_return: jax.Array
    """Return so far of each environment's current episode."""
    episode_length: jax.Array
    updates: jax.Array
    """Updates done so far (int32); env steps = updates * steps_per_update * num_envs."""


def init_train_state(key: jax.Array, env, learner: Learner, num_envs: int) -> TrainState:
    """A fresh single-seed state; `env` is the batched (wrapped) environment."""
    k_env, k_learner, k_loop = jax.random.split(key, 3)
    env_state = env.reset(jax.random.split(k_env, num_envs))
    return TrainState(
        learner=learner.init(k_learner),
        env_state=env_state,
        key=k_loop,
        episode_return=jnp.zeros(num_envs),
        episode_length=jnp.zeros(num_envs),
        updates=jnp.zeros((), jnp.int32),
    )


def state_specs(state: TrainState, learner: Learner):
    """PartitionSpecs of a seed-batched `TrainState`: seed axis first and replicated, each env axis
    split over the "dev" mesh axis, everything else replicated."""
    axes = TrainState(
        learner=learner.env_axes(state.learner),
        env_state=jax.tree.map(lambda _: 0, state.env_state),
        key=None, episode_return=0, episode_length=0, updates=None,
    )
    treedef = jax.tree.structure(state)
    try:  # one axis per leaf of the state; an empty subtree of it (a None field) takes none
        axis_leaves = treedef.flatten_up_to(axes)
    except (ValueError, TypeError) as e:
        raise ValueError("learner.env_axes returned a tree that does not match the learner state") from e
    specs = [P() if a is None else P(*([None] * (a + 1) + [AXIS])) for a in axis_leaves]
    return jax.tree.unflatten(treedef, specs)


def episode_metric_names(env_state) -> list[str]:
    return sorted(env_state.metrics)


def make_chunk(env, learner: Learner, par: Parallel):
    """The single-seed, single-device-view chunk: `chunk(state, n_updates) -> (state, metrics)`."""
    steps = learner.steps_per_update

    def rollout(ls, carry, key):
        def step(c, k):
            env_state, ep_ret, ep_len, acc = c
            # Named scopes label the pieces in profiler traces (benchmarks/trace_summary.py).
            with jax.named_scope("act"):
                action, extras = learner.act(ls, env_state.obs, k, par)
            with jax.named_scope("env_step"):
                nxt = env.step(env_state, action)
            truncation = nxt.info["truncation"]
            done = nxt.done
            tr = Transition(
                obs=env_state.obs, action=action, reward=nxt.reward,
                termination=done * (1.0 - truncation), truncation=truncation,
                next_obs=nxt.info["final_obs"], extras=extras,
            )
            ep_ret = ep_ret + nxt.reward
            ep_len = ep_len + 1.0
            acc = dict(acc)
            acc["episodes"] = acc["episodes"] + jnp.sum(done)
            acc["episode/return"] = acc["episode/return"] + jnp.sum(done * ep_ret)
            acc["episode/length"] = acc["episode/length"] + jnp.sum(done * ep_len)
            for name, value in nxt.metrics.items():
                acc["episode/" + name] = acc["episode/" + name] + jnp.sum(done * value)
            ep_ret = ep_ret * (1.0 - done)
            ep_len = ep_len * (1.0 - done)
            return (nxt, ep_ret, ep_len, acc), tr

        return jax.lax.scan(step, carry, jax.random.split(key, steps))

    def batch_like(ls, env_state, key):
        """A rollout's batch of transitions in shape and dtype, made from the env state without stepping the env:
        the update's metric shapes follow from it, so tracing the chunk traces the env's step once, not twice."""
        action, extras = learner.act(ls, env_state.obs, key, par)
        done = env_state.done * (1.0 - env_state.info["truncation"])
        one = Transition(obs=env_state.obs, action=action, reward=env_state.reward, termination=done,
                         truncation=env_state.info["truncation"], next_obs=env_state.obs, extras=extras)
        return jax.tree.map(lambda x: jnp.broadcast_to(x, (steps,) + x.shape), one)

    def chunk(state: TrainState, n_updates: jax.Array):
        names = episode_metric_names(state.env_state)
        acc0 = {k: jnp.zeros(()) for k in ["episodes", "episode/return", "episode/length"] + ["episode/" + n for n in names]}
        metrics_shape = jax.eval_shape(
            lambda st: learner.update(st.learner, batch_like(st.learner, st.env_state, st.key), st.key, par)[1], state
        )
        lm0 = jax.tree.map(lambda x: jnp.zeros(x.shape, x.dtype), metrics_shape)

        def one_update(_, carry):
            st, acc, lm = carry
            key, k_roll, k_update = jax.random.split(st.key, 3)
            (env_state, ep_ret, ep_len, acc), batch = rollout(
                st.learner, (st.env_state, st.episode_return, st.episode_length, acc), k_roll
            )
            with jax.named_scope("update"):
                ls, metrics = learner.update(st.learner, batch, k_update, par)
            lm = jax.tree.map(jnp.add, lm, metrics)
            st = TrainState(ls, env_state, key, ep_ret, ep_len, st.updates + 1)
            return st, acc, lm

        new_state, acc, lm = jax.lax.fori_loop(0, n_updates, one_update, (state, acc0, lm0))
        # The loop may have made some leaves weakly typed (env code writing Python floats); keep the
        # input's exact types so the next chunk call does not recompile.
        state = jax.tree.map(lambda x, ref: jax.lax.convert_element_type(x, ref.dtype), new_state, state)
        acc = par.psum(acc)
        count = acc.pop("episodes")
        metrics = {k: v / jnp.maximum(n_updates, 1) for k, v in lm.items()}
        metrics["episodes"] = count
        for k, v in acc.items():
            metrics[k] = jnp.where(count > 0, v / jnp.maximum(count, 1.0), jnp.nan)
        return state, metrics

    return chunk


def episode_metrics(done, reward, metrics: dict, last_steps: int = 10) -> dict:
    """Per-environment metrics of each environment's *first* episode, from a rollout's records.

    `done`, `reward` and each `metrics[name]` are `(steps, envs)`: what `env.step` returned at each
    step (the wrapped env auto-resets, so records after an episode's end belong to later episodes
    and are ignored). An episode ends at its first `done` or, if none, at the last step. Returns
    `(envs,)` arrays: "episode/return", "episode/length", "episode/<metric>" (its value at the
    episode's last step; the env's metrics describe the whole episode there) and
    "episode/<metric>_last{last_steps}" (its mean over the episode's last `last_steps` steps).
    """
    steps = done.shape[0]
    t = jnp.arange(steps)[:, None]
    first_done = jnp.where(jnp.any(done > 0, axis=0), jnp.argmax(done > 0, axis=0), steps - 1)
    alive = t <= first_done
    last = alive & (t > first_done - last_steps)
    out = {
        "episode/return": jnp.sum(reward * alive, axis=0),
        "episode/length": first_done + 1.0,
    }
    for name, value in metrics.items():
        out["episode/" + name] = jnp.take_along_axis(value, first_done[None], axis=0)[0]
        out[f"episode/{name}_last{last_steps}"] = jnp.sum(value * last, 0) / jnp.sum(last, 0)
    return out


def make_evaluate(env, learner: Learner, num_envs: int, episode_length: int, last_steps: int = 10,
                  act=None, per_env: bool = False, record=None, memory=None, copies: int = 1, memory_metrics=None):
    """`evaluate(learner_state, key) -> metrics`: one episode per env with the deterministic policy.

    `env` is the batched environment. Each env's *first* episode counts (it ends by termination or
    at the time limit). Reported (`episode_metrics`): mean return and length, each env metric at the
    episode's last step, and `<metric>_last{last_steps}`, its mean over the episode's last
    `last_steps` steps (the paper reports the distance to the target that way).

    `act(learner_state, state, start, key) -> actions` replaces the learner's deterministic policy
    (`learner.policy(learner_state, state.obs)`): policies that read the env state rather than the
    observation, such as the baselines of `agents.baselines`. `start` is the state after reset (the
    first episode's initial state), `key` a fresh key per step. `per_env=True` returns `(num_envs,)`
    arrays instead of means. `record(state) -> pytree` additionally returns, as `(metrics, records)`,
    that pytree for the reset state and after every step, stacked along a leading time axis of
    `episode_length + 1` (e.g. joint positions for rendering).
    `memory(start) -> pytree` gives `act` a state of its own across steps (a planner's plan, `agents.planner`):
    it is then called `act(learner_state, state, start, key, mem)` and returns `(actions, mem)`;
    `memory_metrics(mem) -> {name: (envs,)}` adds per-step metrics read off the memory after each step (reported as
    the env's are: "episode/<name>" is its value at the episode's last step, e.g. a count kept in the memory).
    The reset keys depend on `key` alone, so every policy sees the same episodes for one key.
    `copies` > 1: the batch holds the `num_envs` episodes `copies` times over, copy after copy (policies side by
    side, `make_evaluate_stacked`); the outputs then cover all `copies * num_envs` envs.
    """
    if act is None:
        act = lambda ls, state, start, k: learner.policy(ls, state.obs)

    def evaluate(ls, key):
        start = env.reset(jnp.concatenate([jax.random.split(key, num_envs)] * copies))
        act_keys = jax.random.split(jax.random.fold_in(key, 1), episode_length)

        def step(carry, k):
            s, mem = carry
            if memory is None:
                action = act(ls, s, start, k)
            else:
                action, mem = act(ls, s, start, k, mem)
            nxt = env.step(s, action)
            extra = () if record is None else record(nxt)
            metrics = nxt.metrics if memory_metrics is None else {**nxt.metrics, **memory_metrics(mem)}
            return (nxt, mem), (nxt.done, nxt.reward, metrics, extra)

        first = () if memory is None else memory(start)
        _, (done, reward, metrics, records) = jax.lax.scan(step, (start, first), act_keys)
        out = episode_metrics(done, reward, metrics, last_steps)
        if not per_env:
            out = {k: jnp.mean(v) for k, v in out.items()}
        if record is None:
            return out
        records = jax.tree.map(lambda a, b: jnp.concatenate([a[None], b]), record(start), records)
        return out, records

    return evaluate


def make_evaluate_stacked(env, learner: Learner, num_envs: int, episode_length: int, last_steps: int = 10,
                          stochastic: bool = False, per_env: bool = False, record=None, unit_act=None,
                          unit_memory=None, memory_metrics=None):
    """`evaluate(learner_states, key)`: `make_evaluate`'s evaluation of every learner state along a leading axis
    (trained seeds), each on the same `num_envs` episodes, outputs stacked along that axis (records: `(units, T + 1,
    num_envs, ...)`). The units' envs run side by side as one batch in one scan; `jax.vmap` over the units gives the
    same numbers, but batching a scan traces its body again (and the physics' substep scan inside it).
    `stochastic`: actions drawn from the policy (one key per step,
    the same for every unit, as a `vmap` with a shared key). `unit_act(params, env_states, key, mem) -> (actions, mem)`
    replaces the policy over one unit's batch of env states, with a memory per env across steps that
    `unit_memory(start)` begins for every env of the batch (`agents.shield`, which reads the env state);
    `memory_metrics` as `make_evaluate`'s, over the memory of all units' envs."""

    if memory_metrics is not None and unit_act is None:
        raise ValueError("memory_metrics without unit_act is invalid: allowed only with unit_act and unit_memory (the "
                         "memory it reads).")

    def evaluate(states, key):
        units = jax.tree.leaves(states)[0].shape[0]

        def policy(state, obs, k):
            return learner.stochastic_policy(state, obs, k) if stochastic else learner.policy(state, obs)

        def act(states, env_state, start, k):
            obs = env_state.obs.reshape(units, num_envs, *env_state.obs.shape[1:])
            actions = jax.vmap(policy, in_axes=(0, 0, None))(states, obs, k)
            return actions.reshape(units * num_envs, *actions.shape[2:])

        by_unit = lambda tree: jax.tree.map(lambda x: x.reshape(units, num_envs, *x.shape[1:]), tree)
        flat = lambda tree: jax.tree.map(lambda x: x.reshape(units * num_envs, *x.shape[2:]), tree)

        def act_with_memory(states, env_state, start, k, mem):
            actions, mem = jax.vmap(unit_act, in_axes=(0, 0, None, 0))(states, by_unit(env_state), k, by_unit(mem))
            return flat(actions), flat(mem)

        if unit_act is None:
            run = make_evaluate(env, learner, num_envs, episode_length, last_steps, act=act, per_env=True,
                                record=record, copies=units)
        else:
            run = make_evaluate(env, learner, num_envs, episode_length, last_steps, act=act_with_memory, per_env=True,
                                record=record, memory=unit_memory, copies=units, memory_metrics=memory_metrics)
        out, records = run(states, key) if record is not None else (run(states, key), None)
        out = {k: v.reshape(units, num_envs) if per_env else jnp.mean(v.reshape(units, num_envs), axis=1)
               for k, v in out.items()}
        if record is None:
            return out
        split = lambda r: jnp.swapaxes(r.reshape(r.shape[0], units, num_envs, *r.shape[2:]), 0, 1)
        return out, jax.tree.map(split, records)

    return evaluate


def over_seeds(fn, num_seeds: int):
    """`fn(state, x)` applied to every seed of a seed-batched `state` (`x` shared): `jax.vmap` over
    the leading axis, or with one seed `fn` itself on the squeezed state. Same numbers up to float
    rounding; XLA compiles a size-1 batch axis into a different, slower program (results: throughput study)."""
    if num_seeds > 1:
        return jax.vmap(fn, in_axes=(0, None))
    squeeze = lambda tree: jax.tree.map(lambda a: a[0], tree)
    expand = lambda tree: jax.tree.map(lambda a: a[None], tree)
    return lambda state, x: expand(fn(squeeze(state), x))


class Programs:
    """The compiled pieces of one run: `init(keys)`, `chunk(state, n)`, `evaluate(state, keys)`.

    Built once per (env config, algorithm config, seeds, devices); `agents.driver` runs them.
    """

    def __init__(self, env, eval_env, learner: Learner, num_envs: int, num_seeds: int, devices,
                 eval_envs: int, episode_length: int, eval_last_steps: int = 10, multi_device: str = "gspmd"):
        self.env, self.learner, self.num_envs, self.num_seeds = env, learner, num_envs, num_seeds
        self.devices = list(devices)
        nd = len(self.devices)
        gspmd = nd > 1 and multi_device == "gspmd"
        # shard_map: each device runs the chunk on its envs and the learners' collectives combine them.
        # gspmd: the chunk is written for all envs at once (no collectives) and XLA's partitioner
        # splits it along the sharded env axes of the state.
        par = Parallel(num_envs, nd, AXIS) if nd > 1 and not gspmd else Parallel(num_envs)
        self.parallel = par
        self.mesh = Mesh(self.devices, (AXIS,))

        init_one = lambda key: init_train_state(key, env, learner, num_envs)
        init_all = jax.vmap(init_one)
        abstract = jax.eval_shape(init_all, jax.ShapeDtypeStruct((num_seeds, 2), jnp.uint32))
        self.specs = state_specs(abstract, learner)
        self.shardings = jax.tree.map(lambda s: NamedSharding(self.mesh, s), self.specs)
        self.abstract_state = jax.tree.map(
            lambda a, s: jax.ShapeDtypeStruct(a.shape, a.dtype, sharding=s), abstract, self.shardings
        )
        self.init = jax.jit(init_all, out_shardings=self.shardings)

        chunk = over_seeds(make_chunk(env, learner, par), num_seeds)
        if gspmd:
            replicated = NamedSharding(self.mesh, P())
            self.chunk = jax.jit(chunk, in_shardings=(self.shardings, replicated),
                                 out_shardings=(self.shardings, replicated), donate_argnums=0)
        else:
            if nd > 1:
                # check_vma=False: MJX's constraint solver (a lax.cond inside a scan) fails shard_map's
                # varying-axis type check; learners therefore average gradients explicitly.
                chunk = jax.shard_map(chunk, mesh=self.mesh, in_specs=(self.specs, P()), out_specs=(self.specs, P()),
                                      check_vma=False)
            self.chunk = jax.jit(chunk, donate_argnums=0)

        self.evaluate = jax.jit(make_evaluate_stacked(eval_env, learner, eval_envs, episode_length, eval_last_steps))

    def chunk_ahead(self, keys) -> Ahead:
        """Compiles `chunk` in a thread for the state `init(keys)` will return: a fresh run's two compilations overlap
        (the chunk's, the larger, while `init` compiles and runs). `init` is traced here, before the thread starts,
        so no env code is traced in two threads at once (`envs.fast_mjx` patches MJX process-wide while tracing)."""
        return compiling(self.chunk, self.init.eval_shape(keys), jnp.int32(1), what="the training chunk")

    def evaluation_ahead(self, learner_states) -> Ahead:
        """Compiles `evaluate` in a thread for learner states shaped and placed like `learner_states` (read now: the
        arrays may be donated to a chunk meanwhile), so that calling it later runs at once."""
        like = jax.tree.map(lambda x: jax.ShapeDtypeStruct(x.shape, x.dtype, sharding=x.sharding), learner_states)
        return compiling(self.evaluate, like, jax.eval_shape(jax.random.PRNGKey, 0), what="the evaluation")
