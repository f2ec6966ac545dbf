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
    """ValueError at trace time unless `action` has shape `expected`: JAX would broadcast a (4,) or
    () action over every joint, or fail with a broadcasting error naming no argument."""
    shape = tuple(jnp.shape(action))
    if shape != tuple(expected):
        raise ValueError(f"action of shape {shape} is invalid for {what}: allowed is shape {tuple(expected)}.")


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
