"""Obstacle motions of the reach-avoid task. Not in the paper, whose Discussion names dynamic obstacles as
future work; `ReachAvoidConfig.obstacle_motion` picks one by name.

A motion is a closed-form function of episode time: `state(params, t, period, region)` gives each
obstacle's centre and velocity at time `t` (s). Nothing is integrated, so the collision check can ask
for the obstacles at every physics substep, and an episode's trajectory follows from the parameters
drawn at reset. Parameters are arrays with leading axes (obstacles, and candidates while sampling).
"""

from __future__ import annotations

from typing import Callable, NamedTuple

import jax
import jax.numpy as jnp

MAX_OBSTACLES = 8
"""Most obstacles per episode, the range the tests cover: each obstacle adds its own unrolled sampling
and collision checks to the compiled step."""


class Motion(NamedTuple):
    sample: Callable
    """(key, centers [..., 3], speeds [...], period, region) -> params (a dict of arrays)."""
    state: Callable
    """(params, t, period, region) -> (positions [..., 3], velocities [..., 3]) at time t."""
    moves: bool
    """False: the obstacles keep their sampled centres and no parameters are stored."""


def random_directions(key, shape):
    """Unit vectors uniform on the sphere, `shape + (3,)`."""
    d = jax.random.normal(key, shape + (3,))
    return d / (jnp.linalg.norm(d, axis=-1, keepdims=True) + 1e-9)


def reflect(x, low, high):
    """`x` folded into [low, high] by mirror reflections at both ends (a triangle wave of period
    2 (high - low)), and the sign (+1 or -1) the folding gives a velocity."""
    width = high - low
    u = jnp.mod(x - low, 2.0 * width)
    return low + width - jnp.abs(u - width), jnp.where(u < width, 1.0, -1.0)


def _static_sample(key, centers, speeds, period, region):
    return {"center": centers}


def _static_state(params, t, period, region):
    return params["center"], jnp.zeros_like(params["center"])


def _linear_sample(key, centers, speeds, period, region):
    return {"center": centers, "velocity": random_directions(key, speeds.shape) * speeds[..., None]}


def _linear_state(params, t, period, region):
    """Constant velocity from the centre, bounced off the faces of the sampling cube."""
    position, sign = reflect(params["center"] + params["velocity"] * t, -region, region)
    return position, sign * params["velocity"]


def _sinusoid_sample(key, centers, speeds, period, region):
    """Peak speed `speeds` (amplitude = speed * period / 2 pi), capped so that centre +- amplitude
    stays in the cube along the direction."""
    k_dir, k_phase = jax.random.split(key)
    direction = random_directions(k_dir, speeds.shape)
    room = jnp.min((region - jnp.abs(centers)) / (jnp.abs(direction) + 1e-9), axis=-1)
    amplitude = jnp.minimum(speeds * period / (2.0 * jnp.pi), room)
    phase = jax.random.uniform(k_phase, speeds.shape, maxval=2.0 * jnp.pi)
    return {"center": centers, "amplitude": direction * amplitude[..., None], "phase": phase}


def _sinusoid_state(params, t, period, region):
    omega = 2.0 * jnp.pi / period
    angle = (omega * t + params["phase"])[..., None]
    return params["center"] + params["amplitude"] * jnp.sin(angle), params["amplitude"] * omega * jnp.cos(angle)


MOTIONS: dict[str, Motion] = {
    "static": Motion(_static_sample, _static_state, moves=False),
    "linear": Motion(_linear_sample, _linear_state, moves=True),
    "sinusoid": Motion(_sinusoid_sample, _sinusoid_state, moves=True),
}
"""The obstacle motions by name (`ReachAvoidConfig.obstacle_motion`)."""
