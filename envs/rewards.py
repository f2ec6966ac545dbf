"""Reward terms of the paper (section "Reward formulation"), one small function each.

All take distances in metres and return per-step rewards; the task combines them in
`envs.arm.ArmEnv.reward`. A step that collides earns nothing (and `collision_penalty` is
subtracted): collisions are penalised by ending the episode, which forfeits future reward.
"""

import jax.numpy as jnp


def sparse(in_target, w_reach=1.0):
    """+w_reach on a step that ends in the target, 0 otherwise."""
    return w_reach * in_target


def semi_sparse(in_target, distance, w_reach, w_dist, d_max):
    """Paper eq. (1): w_reach * [in target] + w_dist * (2 d_max - d).

    Subtracting the distance from twice the reach keeps the reward non-negative, so ending the
    episode early (by colliding) never pays.
    """
    return w_reach * in_target + w_dist * (2.0 * d_max - distance)


def dense(distance, w_dist, alpha):
    """Paper eq. (2): w_dist * exp(-alpha * d); independent of the target size."""
    return w_dist * jnp.exp(-alpha * distance)


def l2_penalty(values, weight):
    """weight * ||values||_2, for the optional joint velocity and acceleration penalties."""
    return weight * jnp.linalg.norm(values, axis=-1)


def obstacle_proximity(link_distances, w_obst, tau):
    """Paper eq. (3): w_obst * sum_i max(0, 1 - d_i / tau), a penalty (subtract it)."""
    return w_obst * jnp.sum(jnp.maximum(0.0, 1.0 - link_distances / tau), axis=-1)


def joint_limit_proximity(qpos, low, high, weight, margin):
    """weight * sum_i max(0, 1 - m_i / margin), m_i = the joint's distance to the nearer end of its range.

    Not in the paper: eq. (3)'s form applied to the joint range, a penalty (subtract it) that grows
    from 0 at `margin` radians from a limit to `weight` per joint at the limit.
    """
    to_limit = jnp.minimum(qpos - low, high - qpos)
    return weight * jnp.sum(jnp.maximum(0.0, 1.0 - to_limit / margin), axis=-1)
