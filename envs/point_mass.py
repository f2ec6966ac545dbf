"""A pure-JAX point mass that must reach a goal: a probe task for learners.

It compiles in about a second and runs thousands of steps per second on a CPU, so algorithm
changes can be checked in seconds (tests, `notebooks/02_edit_an_algorithm.ipynb`) before spending
GPU time on the arms. It has the arm tasks' shape: reach a sampled target, a dense reward, a real
termination (leaving the arena, or a non-finite action as the arms' `physics_nan`) next to
time-out truncation.
"""

from __future__ import annotations

import dataclasses

import jax
import jax.numpy as jnp

from envs import validation
from envs.base import Env, State, check_action, check_state


@dataclasses.dataclass(frozen=True)
class PointMassConfig:
    """Options of the point-mass probe task."""

    dim: int = 2
    """Dimension of the space the point moves in."""
    episode_length: int = 50
    """Steps per episode before truncation (used by `envs.wrappers.wrap`)."""
    dt: float = 0.1
    """Seconds per step."""
    max_speed: float = 1.0
    """Speed (units/s) commanded by an action of magnitude 1 in each coordinate."""
    goal_radius: float = 0.1
    """Distance under which the point is in the goal."""
    arena: float = 1.5
    """Leaving the cube [-arena, arena]^dim terminates the episode (a real termination)."""
    alpha: float = 5.0
    """Sharpness of the dense reward exp(-alpha * distance)."""

    def validate(self) -> None:
        for name in ("dim", "episode_length"):
            validation.integer(name, getattr(self, name), 1)
        for name in ("dt", "max_speed", "goal_radius", "arena", "alpha"):
            validation.positive(name, getattr(self, name))


class PointMass(Env):
    """Velocity-controlled point; observation = (position, goal, goal - position). Build it with `envs.make` or
    `envs.from_config`, which check the config: the constructor trusts it."""

    def __init__(self, config: PointMassConfig = PointMassConfig()):
        self.config = config

    @property
    def observation_size(self) -> int:
        return 3 * self.config.dim

    @property
    def action_size(self) -> int:
        return self.config.dim

    def _obs(self, pos, goal):
        return jnp.concatenate([pos, goal, goal - pos])

    def _metrics(self, dist, reached, nonfinite):
        return {"distance": dist, "in_target": (dist < self.config.goal_radius).astype(jnp.float32),
                "target_reached": reached, "physics_nan": nonfinite.astype(jnp.float32)}

    def reset(self, rng: jax.Array) -> State:
        k_pos, k_goal = jax.random.split(rng)
        pos = jax.random.uniform(k_pos, (self.config.dim,), minval=-1.0, maxval=1.0)
        goal = jax.random.uniform(k_goal, (self.config.dim,), minval=-1.0, maxval=1.0)
        dist = jnp.linalg.norm(goal - pos)
        reached = (dist < self.config.goal_radius).astype(jnp.float32)
        return State(
            pipeline_state={"pos": pos},
            obs=self._obs(pos, goal),
            reward=jnp.zeros(()),
            done=jnp.zeros(()),
            metrics=self._metrics(dist, reached, jnp.array(False)),
            info={"goal": goal, "reached": reached},
        )

    def step(self, state: State, action: jax.Array) -> State:
        cfg = self.config
        check_state(state, "one point-mass env")
        check_action(action, (self.action_size,), "one point-mass env")
        goal = state.info["goal"]
        # A non-finite action ends the episode where the point was (as the arms' physics_nan):
        # NaN never reaches a position, observation or metric.
        nonfinite = ~jnp.all(jnp.isfinite(action))
        moved = state.pipeline_state["pos"] + cfg.dt * cfg.max_speed * jnp.clip(action, -1.0, 1.0)
        pos = jnp.where(nonfinite, state.pipeline_state["pos"], moved)
        dist = jnp.linalg.norm(goal - pos)
        outside = jnp.any(jnp.abs(pos) > cfg.arena)
        failed = outside | nonfinite
        reached = jnp.maximum(state.info["reached"], (dist < cfg.goal_radius) & ~failed)
        reward = jnp.where(failed, 0.0, jnp.exp(-cfg.alpha * dist))
        return state.replace(
            pipeline_state={"pos": pos},
            obs=self._obs(pos, goal),
            reward=reward,
            done=failed.astype(jnp.float32),
            metrics={**state.metrics, **self._metrics(dist, reached, nonfinite)},
            info={**state.info, "reached": reached},
        )
