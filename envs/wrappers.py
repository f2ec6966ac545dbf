"""Wrappers for episode length, auto-reset and batching.

Typical use: `env = wrap(envs.make("ur5e-reach"))`, then `state = env.reset(jax.random.split(key,
n))` and `state = env.step(state, actions)` on batches of `n` environments.

Two deliberate differences from Brax's training wrappers:
- Auto-reset draws a *fresh* initial state (pose, target, obstacle) from the environment's own
  sampler. Brax restores one cached first state per environment, which collapses the start /
  goal distribution to `num_envs` fixed episodes; `restarts="first"` does the same, to measure what
  that does (the paper trained with Brax's wrappers; results/fidelity).
- The terminal observation of a finished episode is kept in `info["final_obs"]`, so learners can
  bootstrap truncated episodes from it (truncation is not termination).
"""

from __future__ import annotations

import jax
import jax.numpy as jnp

from envs.base import Env, State, check_action

RESTARTS = ("fresh", "first")
"""How auto-reset starts the next episode: `fresh` samples it, `first` repeats the env's first initial state."""


class Wrapper(Env):
    """Forwards everything to the wrapped environment."""

    def __init__(self, env: Env):
        self.env = env

    def reset(self, rng: jax.Array) -> State:
        return self.env.reset(rng)

    def step(self, state: State, action: jax.Array) -> State:
        return self.env.step(state, action)

    @property
    def observation_size(self) -> int:
        return self.env.observation_size

    @property
    def action_size(self) -> int:
        return self.env.action_size

    @property
    def backend(self) -> str:
        return self.env.backend

    @property
    def unwrapped(self) -> Env:
        return self.env.unwrapped

    def __getattr__(self, name):
        # Attributes such as `config` or `robot` of the wrapped environment stay reachable.
        if name == "env":
            raise AttributeError(name)
        return getattr(self.env, name)


class EpisodeWrapper(Wrapper):
    """Ends episodes after `episode_length` steps and flags them as truncated, not terminated.

    Adds `info["steps"]` (steps taken in the episode) and `info["truncation"]` (1.0 on the step
    where the time limit, and not a termination, ended the episode).
    """

    def __init__(self, env: Env, episode_length: int):
        super().__init__(env)
        if int(episode_length) < 1:
            raise ValueError(f"episode_length={episode_length!r} is invalid: allowed is an integer >= 1.")
        self.episode_length = int(episode_length)

    def reset(self, rng: jax.Array) -> State:
        state = self.env.reset(rng)
        state.info["steps"] = jnp.zeros((), jnp.int32)
        state.info["truncation"] = jnp.zeros(())
        return state

    def step(self, state: State, action: jax.Array) -> State:
        state = self.env.step(state, action)
        steps = state.info["steps"] + 1
        out_of_time = steps >= self.episode_length
        # float32, not weakly typed: the carry of a scan / jitted loop keeps one type
        truncation = jnp.where(out_of_time & (state.done == 0), 1.0, 0.0).astype(jnp.float32)
        state.info["steps"] = steps
        state.info["truncation"] = truncation
        return state.replace(done=jnp.maximum(state.done, truncation))


class AutoResetWrapper(Wrapper):
    """Starts a freshly sampled episode in the same step as the previous one ends.

    On a step with `done == 1` the returned state carries the new episode's `obs`,
    `pipeline_state` and `info`, while `reward`, `done`, `metrics`, `info["truncation"]` and
    `info["final_obs"]` (the terminal observation) describe the step that ended the old one.
    The reset key lives in `info["reset_key"]`, so the whole thing stays a pure function.
    `restarts="first"`: every episode of an env restarts from that env's first initial state (its key
    is kept instead of advanced), as Brax's AutoResetWrapper does.
    """

    def __init__(self, env: Env, restarts: str = "fresh"):
        super().__init__(env)
        if restarts not in RESTARTS:
            raise ValueError(f"restarts={restarts!r} is unknown: allowed are {', '.join(RESTARTS)}.")
        self.restarts = restarts

    def reset(self, rng: jax.Array) -> State:
        rng, reset_key = jax.random.split(rng)
        state = self.env.reset(rng)
        state.info["reset_key"] = rng if self.restarts == "first" else reset_key
        state.info["final_obs"] = state.obs
        return state

    def step(self, state: State, action: jax.Array) -> State:
        if self.restarts == "first":  # the key of the env's first episode, again
            reset_key = next_key = state.info["reset_key"]
        else:
            reset_key, next_key = jax.random.split(state.info["reset_key"])
        stepped = self.env.step(state, action)
        fresh = self.env.reset(reset_key)
        done = stepped.done > 0

        def pick(new, old):
            # `done` is a scalar for one env, or (n,) if this wrapper sits outside a vmap.
            return jnp.where(jnp.reshape(done, done.shape + (1,) * (old.ndim - done.ndim)), new, old)

        # Everything not listed in `fresh.info` (added by outer wrappers) is kept as it is.
        info = dict(stepped.info)
        for key, value in fresh.info.items():
            info[key] = jax.tree.map(pick, value, stepped.info[key])
        info["truncation"] = stepped.info.get("truncation", jnp.zeros(()))
        info["final_obs"] = stepped.obs
        info["reset_key"] = next_key
        return stepped.replace(
            pipeline_state=jax.tree.map(pick, fresh.pipeline_state, stepped.pipeline_state),
            obs=pick(fresh.obs, stepped.obs),
            info=info,
        )


class NoAutoResetWrapper(AutoResetWrapper):
    """AutoResetWrapper's reset (for one key the same initial states and `info` keys as the training
    stack) without its auto-reset: an env whose episode ended keeps stepping its terminal state.
    For evaluation, which counts each env's first episode only: no fresh episode is sampled every
    step, and recorded poses end where the episode did."""

    def step(self, state: State, action: jax.Array) -> State:
        return self.env.step(state, action)


class VmapWrapper(Wrapper):
    """Batches an environment with `jax.vmap`.

    `reset` takes either a batch of keys, shape `(n, 2)`, or a single key together with
    `batch_size` given at construction.
    """

    def __init__(self, env: Env, batch_size: int | None = None):
        super().__init__(env)
        self.batch_size = batch_size

    def reset(self, rng: jax.Array) -> State:
        if self.batch_size is not None and rng.ndim == 1:
            rng = jax.random.split(rng, self.batch_size)
        return jax.vmap(self.env.reset)(rng)

    def step(self, state: State, action: jax.Array) -> State:
        n = jnp.shape(state.done)[0]
        check_action(action, (n, self.env.action_size), f"a batch of {n} envs (one action per env)")
        return jax.vmap(self.env.step)(state, action)


def wrap(env: Env, episode_length: int | None = None, batch_size: int | None = None, autoreset: bool = True,
         restarts: str = "fresh") -> Env:
    """The standard training stack: episode limit, fresh auto-reset, then vmap.

    `episode_length` defaults to the environment's `config.episode_length`. `autoreset=False`: the
    same stack and initial states, each env staying in its first episode (`NoAutoResetWrapper`).
    `restarts`: `fresh` samples every episode anew, `first` restarts each env from its first initial state.
    """
    if episode_length is None:
        config = getattr(env.unwrapped, "config", None)
        if config is None or not hasattr(config, "episode_length"):
            raise ValueError("episode_length=None needs an environment with config.episode_length; pass it explicitly.")
        episode_length = config.episode_length
    episodes = EpisodeWrapper(env, episode_length)
    reset = AutoResetWrapper(episodes, restarts) if autoreset else NoAutoResetWrapper(episodes)
    return VmapWrapper(reset, batch_size=batch_size)
