"""Reward terms of the paper (section "Reward formulation"), one small function each.

All take distances in metres and return per-step rewards; the task names and combines them in
`envs.arm.ArmEnv.reward_terms` (its formulation from `TASK_REWARDS`, its penalties from `ArmEnv.penalties`).
A step that collides earns nothing (and `collision_penalty` is subtracted): collisions are penalised by
ending the episode, which forfeits future reward.
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


def proximity(distances, weight, threshold):
    """weight * sum_i max(0, 1 - d_i / threshold): 0 beyond `threshold`, `weight` per item at d_i = 0."""
    return weight * jnp.sum(jnp.maximum(0.0, 1.0 - distances / threshold), axis=-1)


def obstacle_proximity(link_distances, w_obst, tau):
    """Paper eq. (3): the proximity penalty of the links' distances to the obstacle (subtract it)."""
    return proximity(link_distances, w_obst, tau)


def joint_limit_proximity(qpos, low, high, weight, margin):
    """Not in the paper: eq. (3)'s penalty over each joint's distance to the nearer end of its range,
    from 0 at `margin` radians from a limit to `weight` per joint at the limit (subtract it)."""
    return proximity(jnp.minimum(qpos - low, high - qpos), weight, margin)


TASK_REWARDS = {
    "sparse": lambda cfg, distance, in_target, d_max: sparse(in_target, cfg.w_reach),
    "semi_sparse": lambda cfg, distance, in_target, d_max: semi_sparse(in_target, distance, cfg.w_reach, cfg.w_dist,
                                                                       d_max),
    "dense": lambda cfg, distance, in_target, d_max: dense(distance, cfg.w_dist, cfg.alpha),
}
"""The task's formulation (`ReachConfig.reward`): name -> f(config, distance, in_target, d_max)."""
