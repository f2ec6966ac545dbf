"""Gymnasium bridge: our jitted, batched environments as a `gymnasium.vector.VectorEnv`, numpy in and
numpy out, so that torch-based libraries (Stable-Baselines3, CleanRL) can train on our tasks.

    import stable_baselines3
    from envs import gymnasium as eg

    vec = eg.make_vec("ur5e-reach", num_envs=16, substeps=20)      # options as in `envs.make`
    obs, infos = vec.reset(seed=0)                                  # (16, obs_size) float32
    actions = vec.action_space.sample()                             # (16, action_size) in [-1, 1]
    obs, rewards, terminations, truncations, infos = vec.step(actions)
    if "final_obs" in infos:                                        # some episodes ended this step
        ended = infos["_final_obs"]                                 # == terminations | truncations
        last_obs = infos["final_obs"][ended]                        # their terminal observations
        reached = infos["final_info"]["target_reached"][ended]      # and their episode metrics

    env = eg.make("point-mass")                                     # one `gymnasium.Env`, for checkers
    model = stable_baselines3.PPO("MlpPolicy", eg.to_sb3(vec))      # SB3 (optional dependency)

Autoreset mode: `AutoresetMode.SAME_STEP`, in `metadata["autoreset_mode"]`. Our batched env
(`envs.wrap`) starts a freshly sampled episode in the step that ends the old one, so this is its
faithful image, with no extra step and no buffering. On such a step `rewards`, `terminations` and
`truncations` describe the step that ended the episode, `obs` is the first observation of the next
episode, and, as Gymnasium specifies for that mode (and its `SyncVectorEnv` produces):
- `infos["final_obs"]`: object array of length `num_envs`, the terminal observation where the
  episode ended and `None` elsewhere; `infos["_final_obs"]`: the boolean mask of ended episodes.
- `infos["final_info"]`: the step info of the ended episodes (`{metric: array, "_metric": mask}`);
  `infos["_final_info"]`: the same mask.
- Top-level `infos[metric]` are the per-step metrics (`target_reached`, `distance`,
  `obstacle_collision`, ...) of the environments that go on, masked by `infos["_metric"]`; for the
  reset ones they are 0 with mask False, as their reset info is empty (`reset()` returns `{}`).
SAME_STEP is also what learners need: Stable-Baselines3's own `VecEnv` resets in the same step and
hands the terminal observation over as `info["terminal_observation"]` (see `to_sb3`), and
Gymnasium's vector wrappers (`RecordEpisodeStatistics`, ...) read the mode from the metadata.
CleanRL-style loops take `next_done = terminations | truncations` as usual.
Truncation is not termination: `truncations` are the time limit (`info["truncation"]`),
`terminations` are the task's own ends (collision, leaving the arena, reach-and-terminate); never
both. Bootstrap truncated episodes from `final_obs`.

Seeding follows Gymnasium's `SyncVectorEnv`: `reset(seed=s)` gives sub-environment `i` the seed
`s + i` (its JAX key is `jax.random.PRNGKey((s + i) mod 2**32)`); `make(name).reset(seed=s + i)`
samples the same episode. Later episodes are sampled from keys carried in the state, so a seed and
a sequence of actions determine the whole run. `reset()` without a seed draws one from `np_random`.

Physics: on a CPU the arm envs step with MuJoCo's C library (the `backend="auto"` default, see
`envs.physics`), which runs far faster there than MJX; pass `backend="mjx"` for MJX.

Gymnasium is an optional dependency (`pip install -e ".[gym]"`); Stable-Baselines3 is needed only
by `to_sb3`. This module is `envs.gymnasium`: with absolute imports (Python 3) `import gymnasium`
below is the installed package, never this file.
"""

from __future__ import annotations

import functools
from typing import Any, Sequence

import gymnasium as gym
import jax
import jax.numpy as jnp
import numpy as np
from gymnasium import spaces
from gymnasium.vector import AutoresetMode
from gymnasium.vector.utils import batch_space

from envs import registry
from envs.base import Env
from envs.wrappers import wrap

_SEED_MODULUS = 2**32  # JAX PRNG keys are built from 32-bit seeds here


def _strong(state):
    # `envs.wrap`'s step returns some leaves weakly typed (info["truncation"]) where reset does not;
    # the changed signature would compile the whole step a second time (~25 s for an arm on a CPU).
    return jax.tree.map(lambda x: x.astype(x.dtype) if isinstance(x, jax.Array) else x, state)


def _check_seed(seed) -> int:
    if isinstance(seed, (bool, np.bool_)) or not isinstance(seed, (int, np.integer)) or seed < 0:
        raise ValueError(f"seed={seed!r} is invalid: allowed is None or an integer >= 0.")
    return int(seed)


class GymVectorEnv(gym.vector.VectorEnv):
    """A `gymnasium.vector.VectorEnv` over `num_envs` copies of one of our environments.

    All copies advance in one jit-compiled call per `step` (`envs.wrap`: episode limit, fresh
    auto-reset, vmap); arrays cross to numpy once per call. Actions live in `Box(-1, 1)`,
    observations and rewards are float32, terminations and truncations bool. See the module
    docstring for the autoreset mode, the info keys and seeding.

    Attributes: `env` (the unwrapped JAX environment), `wrapped` (the batched JAX environment),
    `episode_length`, `state` (the current batched `envs.State`, None before the first reset).
    """

    metadata: dict[str, Any] = {"autoreset_mode": AutoresetMode.SAME_STEP, "render_modes": ["rgb_array"]}

    def __init__(self, env: Env, num_envs: int, episode_length: int | None = None, render_mode: str | None = None):
        """Wraps the unwrapped environment `env` (from `envs.make`) in `num_envs` copies.

        `episode_length` defaults to the environment's `config.episode_length`; `render_mode` "rgb_array"
        (arm envs) makes `render()` return an image of each copy.
        """
        if isinstance(num_envs, bool) or not isinstance(num_envs, (int, np.integer)) or num_envs < 1:
            raise ValueError(f"num_envs={num_envs!r} is invalid: allowed is an integer >= 1.")
        self.env = env.unwrapped
        self.num_envs = int(num_envs)
        self.wrapped = wrap(self.env, episode_length=episode_length)
        self.episode_length = self.wrapped.episode_length  # forwarded from the EpisodeWrapper
        self.metadata = dict(type(self).metadata)
        self.render_mode = check_render_mode(self.env, render_mode)

        self.single_observation_space = spaces.Box(-np.inf, np.inf, (self.env.observation_size,), np.float32)
        self.single_action_space = spaces.Box(-1.0, 1.0, (self.env.action_size,), np.float32)
        self.observation_space = batch_space(self.single_observation_space, self.num_envs)
        self.action_space = batch_space(self.single_action_space, self.num_envs)

        self.state = None
        self._reset_fn = jax.jit(self._reset_batch)
        self._masked_reset_fn = jax.jit(self._masked_reset_batch)
        self._step_fn = jax.jit(self._step_batch)

    # ------------------------------------------------------------------------------------------
    # Jitted pieces (pure functions of the batched state)

    def _reset_batch(self, seeds):
        state = _strong(self.wrapped.reset(jax.vmap(jax.random.PRNGKey)(seeds)))
        return state, state.obs.astype(jnp.float32)

    def _masked_reset_batch(self, state, seeds, mask):
        fresh, _ = self._reset_batch(seeds)

        def pick(new, old):
            return jnp.where(jnp.reshape(mask, mask.shape + (1,) * (old.ndim - 1)), new, old)

        state = _strong(jax.tree.map(pick, fresh, state))
        return state, state.obs.astype(jnp.float32)

    def _step_batch(self, state, actions):
        state = _strong(self.wrapped.step(state, actions))
        out = {
            "obs": state.obs.astype(jnp.float32),
            "reward": state.reward.astype(jnp.float32),
            "done": state.done > 0,
            "truncation": state.info["truncation"] > 0,
            "final_obs": state.info["final_obs"].astype(jnp.float32),
            "metrics": {k: v.astype(jnp.float32) for k, v in state.metrics.items()},
        }
        return state, out

    # ------------------------------------------------------------------------------------------
    # Gymnasium API

    def _seeds(self, seed) -> np.ndarray:
        """Per-environment 32-bit seeds; seeds `np_random` as Gymnasium's `VectorEnv.reset` does."""
        if seed is None:
            seed = int(self.np_random.integers(0, _SEED_MODULUS))
        elif isinstance(seed, (list, tuple, np.ndarray)):
            seeds = [_check_seed(s) for s in seed]
            if len(seeds) != self.num_envs:
                raise ValueError(f"seed has {len(seeds)} entries: allowed is one per environment ({self.num_envs}).")
            super().reset(seed=seeds[0])
            return np.array([s % _SEED_MODULUS for s in seeds], dtype=np.uint32)
        else:
            seed = _check_seed(seed)
            super().reset(seed=seed)
        offsets = np.arange(self.num_envs, dtype=np.uint64)
        return ((seed % _SEED_MODULUS + offsets) % _SEED_MODULUS).astype(np.uint32)

    def reset(
        self, *, seed: int | Sequence[int] | None = None, options: dict[str, Any] | None = None,
    ) -> tuple[np.ndarray, dict[str, Any]]:
        """Samples fresh episodes; returns `(obs, infos)` with `obs` of shape `(num_envs, obs_size)`.

        `seed`: None (drawn from `np_random`), an int (sub-environment `i` gets `seed + i`) or one
        int per sub-environment. `options` may hold `reset_mask`, a bool array of shape
        `(num_envs,)`: then only those sub-environments restart, the others keep their episode.
        `infos` is empty (our environments have no reset info).
        """
        options = dict(options or {})
        mask = options.pop("reset_mask", None)
        if options:
            raise ValueError(f"reset options {sorted(options)} are unknown: allowed is 'reset_mask'.")
        if mask is not None:
            mask = np.asarray(mask)
            if mask.dtype != np.bool_ or mask.shape != (self.num_envs,) or not mask.any():
                raise ValueError(f"options['reset_mask'] is invalid: allowed is a bool array of shape "
                                 f"({self.num_envs},) with at least one True (got {mask.dtype} {mask.shape}).")
            if self.state is None:
                raise RuntimeError("reset with options['reset_mask'] needs a previous full reset().")
        seeds = jnp.asarray(self._seeds(seed))
        if mask is None:
            self.state, obs = self._reset_fn(seeds)
        else:
            self.state, obs = self._masked_reset_fn(self.state, seeds, jnp.asarray(mask))
        return np.array(obs), {}

    def step(self, actions) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray, dict[str, Any]]:
        """Advances every sub-environment by one step with `actions` of shape `(num_envs,
        action_size)` in [-1, 1] (the environments clip).

        Returns `(obs, rewards, terminations, truncations, infos)` as numpy arrays; ended episodes
        restart in the same step (module docstring: SAME_STEP keys of `infos`).
        """
        if getattr(self, "closed", False):  # gymnasium's VectorEnv.close() sets it
            raise RuntimeError("step() after close(): this env is closed; make a new one.")
        if self.state is None:
            raise RuntimeError("step() before reset(): call reset() first.")
        actions = as_actions(actions, "actions")
        if actions.shape != self.action_space.shape:
            raise ValueError(f"actions have shape {actions.shape}: allowed is {self.action_space.shape} "
                             "(num_envs, action_size).")
        self.state, out = self._step_fn(self.state, jnp.asarray(actions))
        out = jax.device_get(out)  # one transfer of everything the caller sees

        done = np.array(out["done"])
        truncations = np.array(out["truncation"])
        terminations = done & ~truncations
        running = ~done

        infos: dict[str, Any] = {}
        final_info: dict[str, Any] = {}
        for key, value in out["metrics"].items():
            infos[key], infos[f"_{key}"] = np.where(running, value, 0.0).astype(np.float32), running.copy()
            final_info[key], final_info[f"_{key}"] = np.where(done, value, 0.0).astype(np.float32), done.copy()
        if done.any():
            final_obs = np.full(self.num_envs, None, dtype=object)
            for i in np.flatnonzero(done):  # only the ended episodes; the step itself is batched
                final_obs[i] = np.array(out["final_obs"][i])
            infos["final_obs"], infos["_final_obs"] = final_obs, done.copy()
            infos["final_info"], infos["_final_info"] = final_info, done.copy()
        return np.array(out["obs"]), np.array(out["reward"]), terminations, truncations, infos

    def close_extras(self, **kwargs) -> None:
        """Drops the batched state (nothing else holds resources)."""
        self.state = None

    def render(self) -> tuple[np.ndarray, ...] | None:
        """With render_mode "rgb_array", one (height, width, 3) image of each copy's current state; else None."""
        if self.render_mode is None:
            return None
        if self.state is None:
            raise RuntimeError("render() before reset(): call reset() first.")
        from envs import render  # sets up headless OpenGL on first use; the bridge works without it

        return tuple(render.render_state(self.env, self.state, index=i) for i in range(self.num_envs))

    def __repr__(self) -> str:
        return f"GymVectorEnv({type(self.env).__name__}, num_envs={self.num_envs})"


class GymEnv(gym.Env):
    """One of our environments as a single `gymnasium.Env` (no autoreset), e.g. for
    `gymnasium.utils.env_checker.check_env`, SB3's `DummyVecEnv` or interactive use.

    Runs a one-environment `GymVectorEnv`, so `GymEnv` with seed `s + i` samples the same
    episode as sub-environment `i` of a `GymVectorEnv` reset with seed `s`. When an episode ends,
    `step` returns its terminal observation; call `reset()` before stepping again.
    """

    metadata: dict[str, Any] = {"render_modes": ["rgb_array"]}

    def __init__(self, env: Env, episode_length: int | None = None, render_mode: str | None = None):
        """Wraps the unwrapped environment `env`; `episode_length` and `render_mode` as in `GymVectorEnv`."""
        self.vector_env = GymVectorEnv(env, 1, episode_length, render_mode)
        self.observation_space = self.vector_env.single_observation_space
        self.action_space = self.vector_env.single_action_space
        self.render_mode = self.vector_env.render_mode
        self._needs_reset = True

    def reset(self, *, seed: int | None = None, options: dict[str, Any] | None = None) -> tuple[np.ndarray, dict]:
        """Samples a fresh episode; `seed` as in Gymnasium (None draws one from `np_random`).
        `options` must be empty. Returns `(obs, {})`."""
        if options:
            raise ValueError(f"reset options {sorted(options)} are unknown: allowed is none.")
        super().reset(seed=None if seed is None else _check_seed(seed))
        if seed is None:
            seed = int(self.np_random.integers(0, _SEED_MODULUS))
        obs, _ = self.vector_env.reset(seed=seed)
        self._needs_reset = False
        return obs[0], {}

    def step(self, action) -> tuple[np.ndarray, float, bool, bool, dict[str, Any]]:
        """One step with `action` of shape `(action_size,)`; returns `(obs, reward, terminated,
        truncated, info)` with the step's metrics in `info` (numpy float32 scalars)."""
        if self._needs_reset:
            raise RuntimeError("step() needs reset() first (at the start and after an episode ended).")
        action = as_actions(action, "action")
        if action.shape != self.action_space.shape:
            raise ValueError(f"action has shape {action.shape}: allowed is {self.action_space.shape}.")
        obs, rewards, terminations, truncations, infos = self.vector_env.step(action[None])
        terminated, truncated = bool(terminations[0]), bool(truncations[0])
        if terminated or truncated:
            self._needs_reset = True
            obs, infos = infos["final_obs"], infos["final_info"]
        info = {key: value[0] for key, value in infos.items() if not key.startswith("_")}
        return obs[0], float(rewards[0]), terminated, truncated, info

    def close(self) -> None:
        """Releases the underlying vector environment."""
        self.vector_env.close()

    def render(self) -> np.ndarray | None:
        """With render_mode "rgb_array", a (height, width, 3) image of the current state; else None."""
        frames = self.vector_env.render()
        return None if frames is None else frames[0]


def check_render_mode(env: Env, render_mode: str | None) -> str | None:
    """`render_mode` if the env can draw it: None, or "rgb_array" for an arm env (a robot model to render)."""
    if render_mode not in (None, "rgb_array"):
        raise ValueError(f"render_mode={render_mode!r} is invalid: allowed are None and 'rgb_array'.")
    if render_mode and getattr(env, "robot", None) is None:
        raise ValueError(f"render_mode={render_mode!r} is invalid for {type(env).__name__}: allowed is None (only "
                         "the arm envs have a model to render).")
    return render_mode


def as_actions(actions, name: str) -> np.ndarray:
    """`actions` as a float32 array; ValueError naming what came for anything that is not numbers."""
    try:
        array = np.asarray(actions, dtype=np.float32)
    except (TypeError, ValueError):
        raise ValueError(f"{name}={actions!r} is invalid: allowed are numbers in [-1, 1].") from None
    return array


def make_vec(name: str, num_envs: int, *, episode_length: int | None = None, render_mode: str | None = None,
             **options) -> GymVectorEnv:
    """`GymVectorEnv` of `num_envs` copies of `envs.make(name, **options)`.

    Example: `make_vec("ur5e-reach-avoid", 64, obstacle_radius=0.2)`.
    """
    return GymVectorEnv(registry.make(name, **options), num_envs, episode_length, render_mode)


def make(name: str, *, episode_length: int | None = None, render_mode: str | None = None, **options) -> GymEnv:
    """Single `GymEnv` of `envs.make(name, **options)`."""
    return GymEnv(registry.make(name, **options), episode_length, render_mode)


def to_sb3(env: GymVectorEnv):
    """A Stable-Baselines3 `VecEnv` over `env` (SB3 2.x does not accept a Gymnasium `VectorEnv`).

    SB3 resets in the same step too: on an ended episode `info["terminal_observation"]` holds
    the terminal observation and `info["TimeLimit.truncated"]` is True for time-outs, which SB3's
    PPO and SAC use to bootstrap truncated episodes. Each info carries the step's metrics, so
    `VecMonitor(to_sb3(env), info_keywords=("target_reached",))` logs them per episode.
    Needs `stable_baselines3` (imported here only).
    """
    from stable_baselines3.common.vec_env import VecEnv

    return _sb3_vec_env_class(VecEnv)(env)


@functools.cache
def _sb3_vec_env_class(base: type) -> type:
    class SB3VecEnv(base):
        """Stable-Baselines3 `VecEnv` view of a `GymVectorEnv` (built by `to_sb3`)."""

        def __init__(self, env: GymVectorEnv):
            """Wraps `env`; SB3 seeds with `seed()` and resets with `reset()` as usual."""
            self.env = env
            self._actions = None
            super().__init__(env.num_envs, env.single_observation_space, env.single_action_space)

        def reset(self) -> np.ndarray:
            """Resets every sub-environment with the seeds and options set by `seed()` /
            `set_options()` (used once, as in SB3's own VecEnvs)."""
            seeds = None if all(s is None for s in self._seeds) else list(self._seeds)
            options = self._options[0] if all(o == self._options[0] for o in self._options) else None
            if options is None:
                raise ValueError("per-environment reset options differ: allowed are identical ones.")
            obs, _ = self.env.reset(seed=seeds, options=options or None)
            self.reset_infos = [{} for _ in range(self.num_envs)]
            self._reset_seeds()
            self._reset_options()
            return obs

        def step_async(self, actions: np.ndarray) -> None:
            """Stores the actions for `step_wait`."""
            self._actions = actions

        def step_wait(self):
            """One batched step; returns SB3's `(obs, rewards, dones, infos)` with a list of infos."""
            obs, rewards, terminations, truncations, infos = self.env.step(self._actions)
            dones = terminations | truncations
            final = infos.get("final_info", {})
            keys = [k for k in infos if not k.startswith("_") and k not in ("final_obs", "final_info")]
            # Metrics of the step just taken: from `final_info` where the episode ended.
            columns = [np.where(dones, final[k], infos[k]) if k in final else infos[k] for k in keys]
            rows = np.stack(columns, axis=1).tolist() if keys else [[] for _ in range(self.num_envs)]
            out = [dict(zip(keys, row)) for row in rows]
            for i, info in enumerate(out):
                info["TimeLimit.truncated"] = bool(truncations[i] and not terminations[i])
                if dones[i]:
                    info["terminal_observation"] = infos["final_obs"][i]
            return obs, rewards, dones, out

        def close(self) -> None:
            """Closes the wrapped vector environment."""
            self.env.close()

        def get_attr(self, attr_name: str, indices=None) -> list[Any]:
            """The vector environment's attribute, once per requested index (the copies share it)."""
            return [getattr(self.env, attr_name) for _ in self._get_indices(indices)]

        def set_attr(self, attr_name: str, value: Any, indices=None) -> None:
            """Sets the attribute on the vector environment (shared by all copies)."""
            setattr(self.env, attr_name, value)

        def env_method(self, method_name: str, *method_args, indices=None, **method_kwargs) -> list[Any]:
            """Calls the vector environment's method once; its result is repeated per index."""
            result = getattr(self.env, method_name)(*method_args, **method_kwargs)
            return [result for _ in self._get_indices(indices)]

        def env_is_wrapped(self, wrapper_class: type, indices=None) -> list[bool]:
            """Always False: the copies are not Gymnasium-wrapped environments."""
            return [False for _ in self._get_indices(indices)]

    return SB3VecEnv
