"""Target workspaces (paper, "Influence of the workspace size" and its Figure).

Coordinates are world coordinates with the robot base at the origin, the base plane at z = 0 and
the robot's front towards +x. `center` is the workspace centre of the robot (its second joint's
height on the base axis) and `reach` its maximum reach.

- full:     the ball of radius `reach` around `center`: the whole reachable space.
- front:    the x >= 0 half of it (the 180 degrees in front of the robot).
- upper:    its part with z >= 0 (above the base plane: a table-top setting).
- pandagym: PandaGym's reach cube, 30 cm wide, 45 to 75 cm in front of the base, 0 to 30 cm above
            the base plane (panda-gym 3.0.8 `Reach` task, goal range relative to the base).
"""

import jax
import jax.numpy as jnp
import numpy as np

PANDAGYM_LOW = np.array([0.45, -0.15, 0.0], np.float32)
PANDAGYM_HIGH = np.array([0.75, 0.15, 0.3], np.float32)


def contains(workspace: str, points, center, reach):
    """Whether `points` `[..., 3]` lie in the workspace."""
    if workspace == "pandagym":
        return jnp.all((points >= PANDAGYM_LOW) & (points <= PANDAGYM_HIGH), axis=-1)
    inside = jnp.linalg.norm(points - center, axis=-1) <= reach
    if workspace == "front":
        inside &= points[..., 0] >= 0.0
    elif workspace == "upper":
        inside &= points[..., 2] >= 0.0
    return inside


def sample_uniform(workspace: str, key, num: int, center, reach):
    """`num` candidate points uniform in the workspace's bounding shape (ball or cube) and a mask
    of those inside the workspace itself (all of them except for `upper`, whose cut below the
    centre is handled by rejection)."""
    if workspace == "pandagym":
        points = jax.random.uniform(key, (num, 3), minval=PANDAGYM_LOW, maxval=PANDAGYM_HIGH)
        return points, jnp.ones(num, bool)
    k_dir, k_rad = jax.random.split(key)
    direction = jax.random.normal(k_dir, (num, 3))
    direction /= jnp.linalg.norm(direction, axis=-1, keepdims=True) + 1e-9
    radius = reach * jax.random.uniform(k_rad, (num, 1)) ** (1.0 / 3.0)
    offset = direction * radius
    if workspace == "front":
        # The front half-ball is cut through the centre: mirroring is exact and rejects nothing.
        offset = offset.at[:, 0].set(jnp.abs(offset[:, 0]))
    points = center + offset
    return points, contains(workspace, points, center, reach)
