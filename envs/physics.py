"""Physics backends of the arm envs (`ReachConfig.backend`): what steps the robot between two env steps.

- `mjx`: MuJoCo MJX, traced into the env's jitted step (fast on a GPU, slow to compile and run on a CPU).
- `mujoco`: MuJoCo's C library on the CPU's cores through a callback (`envs.native`): no physics to
  compile, laptop-speed evaluation, notebooks and Gymnasium use.
- `auto`: `mujoco` when JAX runs on the CPU, `mjx` on a GPU or TPU.

Both step the same MJCF model with the same options; the task logic around them is shared (`envs.arm`).
"""

from __future__ import annotations

import contextlib
import functools

import jax
import jax.numpy as jnp
from mujoco import mjx

from envs import fast_mjx
from envs.cache import LRU
from envs.config import BACKENDS  # noqa: F401  (the allowed values of ReachConfig.backend)
from envs.native import NativePhysics

STEP_CACHE_SIZE = 16
"""MJX models whose jitted step `mjx_step` keeps (robots built alike share one model: envs/robots/base.py)."""
_STEPS = LRU(STEP_CACHE_SIZE)
"""(id of an MJX model, fast_mjx active) -> its jitted `mjx.step`, which holds the model: a cached model stays alive,
so its id names no other model while the entry exists."""


def mjx_step(model):
    """`mjx.step` of `model` as one jitted function per model (and per whether `envs.fast_mjx` applies): an env
    step traced again, for another task setting of the same robot (a sweep over obstacle sizes, a new training
    program), reuses MuJoCo's traced step instead of tracing it anew, which is most of an arm step's tracing.
    Called inside a trace, it is inlined by XLA like any nested jit."""
    fast = fast_mjx.active()
    return _STEPS.get((id(model), fast), lambda: jax.jit(functools.partial(_step, model, fast)))


def _step(model, fast: bool, data):
    """`mjx.step` traced with `envs.fast_mjx`'s replacements exactly when `fast` (the cache key says so)."""
    with fast_mjx.fast_mjx(True) if fast else contextlib.nullcontext():
        if fast_mjx.active() != fast:
            raise RuntimeError("mjx_step's step for the plain MJX functions was first called inside fast_mjx(); "
                               "call it where it was made.")
        return mjx.step(model, data)


def resolve(backend: str) -> str:
    """The backend `backend` stands for on this machine ("auto": by JAX's default device)."""
    if backend == "auto":
        return "mujoco" if jax.default_backend() == "cpu" else "mjx"
    return backend


class MjxPhysics:
    """MJX stepping inside the env's jitted step."""

    def __init__(self, robot, substeps: int):
        self.robot = robot
        self.substeps = int(substeps)

    def run(self, data, distances):
        """`(data, closest)`: `data` after `substeps` physics steps holding `data.ctrl`, and the
        elementwise minimum of `distances(geom_xpos, geom_xmat, k)` over the configurations each
        substep k started from."""

        step = mjx_step(self.robot.mjx_model)

        def substep(carry, k):
            data, closest = carry
            data = step(data)
            # mjx.step leaves the geom poses of the configuration this substep started from
            closest = jnp.minimum(closest, distances(data.geom_xpos, data.geom_xmat, k))
            return (data, closest), None

        (data, closest), _ = jax.lax.scan(substep, (data, jnp.full(2, jnp.inf, jnp.float32)), jnp.arange(self.substeps))
        return data, closest


PHYSICS = {"mjx": MjxPhysics, "mujoco": NativePhysics}
"""Backend name -> class built as `cls(robot, substeps)`, with `run(data, distances)`."""
