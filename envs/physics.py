"""Physics backends of the arm envs (`ReachConfig.backend`): what steps the robot between two env steps.

- `mjx`: MuJoCo MJX, traced into the env's jitted step (fast on a GPU, slow to compile and run on a CPU).
- `mujoco`: MuJoCo's C library on the CPU's cores through a callback (`envs.native`): no physics to
  compile, laptop-speed evaluation, notebooks and Gymnasium use.
- `auto`: `mujoco` when JAX runs on the CPU, `mjx` on a GPU or TPU.

Both step the same MJCF model with the same options; the task logic around them is shared (`envs.arm`).
"""

from __future__ import annotations

import jax
import jax.numpy as jnp
from mujoco import mjx

from envs.config import BACKENDS  # noqa: F401  (the allowed values of ReachConfig.backend)
from envs.native import NativePhysics


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

        def substep(carry, k):
            data, closest = carry
            data = mjx.step(self.robot.mjx_model, data)
            # mjx.step leaves the geom poses of the configuration this substep started from
            closest = jnp.minimum(closest, distances(data.geom_xpos, data.geom_xmat, k))
            return (data, closest), None

        (data, closest), _ = jax.lax.scan(substep, (data, jnp.full(2, jnp.inf)), jnp.arange(self.substeps))
        return data, closest


PHYSICS = {"mjx": MjxPhysics, "mujoco": NativePhysics}
"""Backend name -> class built as `cls(robot, substeps)`, with `run(data, distances)`."""
