"""The environment interface: an explicit `State` and pure `reset` / `step` functions.

The interface mirrors Brax's `brax.envs.Env` (same `State` fields, same method and property
names), so Brax's wrappers and training functions accept our environments unchanged, while the
core of this project never imports Brax.
"""

from __future__ import annotations

import abc
from typing import Any

import jax
import jax.numpy as jnp
from flax import struct


@struct.dataclass
class State:
    """Everything that changes during an episode. Passed to and returned from `Env.step`.

    The field names are Brax's, so `brax.envs.wrappers` can operate on it.
    """

    pipeline_state: Any
    """Physics state (an `mjx.Data` for the arm environments, a small pytree for probe tasks)."""
    obs: jax.Array
    """Observation of the state, shape `(observation_size,)`."""
    reward: jax.Array
    """Reward of the step that produced this state (0 after `reset`)."""
    done: jax.Array
    """1.0 if the episode ended at this step (termination or, once wrapped, truncation)."""
    metrics: dict[str, jax.Array] = struct.field(default_factory=dict)
    """Per-step scalars describing the episode so far (same keys after `reset` and `step`)."""
    info: dict[str, Any] = struct.field(default_factory=dict)
    """Task bookkeeping (target, obstacle, counters, RNG). Wrappers add `steps`, `truncation`,
    `final_obs`."""


def check_action(action, expected: tuple[int, ...], what: str) -> None:
    """At trace time: TypeError unless `action` is a numeric array (a list, a string or an object array would fail
    inside JAX naming no argument), ValueError unless it has shape `expected` (JAX would broadcast a (4,) or ()
    action over every joint)."""
    if not hasattr(action, "shape") or not hasattr(action, "dtype"):
        raise TypeError(f"action of type {type(action).__name__} is invalid for {what}: allowed is a jax or numpy "
                        f"array of shape {tuple(expected)} (e.g. jnp.asarray(action)).")
    if not (jnp.issubdtype(action.dtype, jnp.number) or jnp.issubdtype(action.dtype, jnp.bool_)):
        raise TypeError(f"action of dtype {action.dtype} is invalid for {what}: allowed is a numeric array.")
    shape = tuple(jnp.shape(action))
    if shape != tuple(expected):
        raise ValueError(f"action of shape {shape} is invalid for {what}: allowed is shape {tuple(expected)}.")


def check_state(state, what: str, qpos_size: int | None = None) -> None:
    """At trace time: TypeError unless `state` is a state (`State`'s fields, so Brax's own State class passes too;
    None or a tuple would fail deep inside the step), and with `qpos_size` ValueError unless its joint positions
    have that length (another robot's state)."""
    if not all(hasattr(state, name) for name in ("pipeline_state", "obs", "info")):
        raise TypeError(f"state of type {type(state).__name__} is invalid for {what}: allowed is the State that "
                        "reset() or step() returned.")
    if qpos_size is not None:
        shape = tuple(jnp.shape(state.pipeline_state.qpos))
        if shape != (qpos_size,):
            raise ValueError(f"state with joint positions of shape {shape} is invalid for {what}: allowed is a "
                             f"state of this env, shape ({qpos_size},) (another robot's or a batch's state?).")


class Env(abc.ABC):
    """A single, unbatched environment. Batch with `jax.vmap` or `envs.wrappers.VmapWrapper`."""

    @abc.abstractmethod
    def reset(self, rng: jax.Array) -> State:
        """Samples a fresh initial state from `rng` (a `jax.random.key` or PRNGKey)."""

    @abc.abstractmethod
    def step(self, state: State, action: jax.Array) -> State:
        """Advances the state by one environment step. Pure: same inputs, same output."""

    @property
    @abc.abstractmethod
    def observation_size(self) -> int:
        """Length of the observation vector."""

    @property
    @abc.abstractmethod
    def action_size(self) -> int:
        """Length of the action vector; actions are expected in [-1, 1]."""

    @property
    def backend(self) -> str:
        """Physics backend name (Brax reads this attribute)."""
        return "mjx"

    @property
    def unwrapped(self) -> Env:
        """The innermost environment (wrappers forward to it)."""
        return self
