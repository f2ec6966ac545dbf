"""The link_pos observation part: CPU MuJoCo's link frames at the observed angles, after a reset and after a step
(whose poses come from the physics, not the reset's kinematics), and the origins of eq. 3's d_i."""

import jax
import jax.numpy as jnp
import mujoco
import numpy as np
import pytest

import envs

LINKS = {"ur5e": ("upper_arm_link", "forearm_link", "wrist_1_link", "wrist_2_link", "wrist_3_link"),
         "panda": ("link2", "link3", "link4", "link5", "link6", "link7", "hand")}
"""The bodies that can touch an obstacle, by name, as the models define them."""


def mujoco_links(env, qpos, names):
    """World positions of the named bodies by CPU MuJoCo's kinematics at `qpos`, `[len(names), 3]`."""
    model = env.robot.mj_model
    data = mujoco.MjData(model)
    data.qpos[:] = qpos
    mujoco.mj_kinematics(model, data)
    return np.stack([data.body(name).xpos for name in names])


@pytest.mark.parametrize("robot", ["ur5e", "panda"])
def test_link_positions_are_cpu_mujocos_link_frames_after_a_reset_and_a_step(robot):
    names, nq = LINKS[robot], 6 if robot == "ur5e" else 7
    env = envs.make(f"{robot}-reach", substeps=2, observation=("joint_pos", "link_pos"))
    assert env.observation_size == nq + 3 * len(names)
    reset = env.reset(jax.random.PRNGKey(5))
    stepped = env.step(reset, jnp.full((env.action_size,), 0.5))
    first, after = np.asarray(reset.obs), np.asarray(stepped.obs)
    np.testing.assert_allclose(first[nq:].reshape(-1, 3), mujoco_links(env, first[:nq], names), atol=1e-5)
    np.testing.assert_allclose(after[nq:].reshape(-1, 3), mujoco_links(env, after[:nq], names), atol=1e-5)
    assert np.abs(after[nq:] - first[nq:]).max() > 1e-4  # the step moved the links (10x the tolerance)


def test_link_positions_are_the_origins_of_the_link_obstacle_distances():
    """Eq. 3's d_i = |p_link - p_obst| - r, nearest obstacle per link, recomputed by hand from the observed parts."""
    env = envs.make("ur5e-reach-avoid", num_obstacles=2, obstacle_radius_range=(0.05, 0.1),
                    observation=("link_pos", "obstacle_pos", "obstacle_radius", "link_obstacle_dist"))
    obs = np.asarray(env.reset(jax.random.PRNGKey(5)).obs)
    links, centers, radii = obs[:15].reshape(5, 3), obs[15:21].reshape(2, 3), obs[21:23]
    by_hand = np.min(np.linalg.norm(links[None] - centers[:, None], axis=-1) - radii[:, None], axis=0)
    np.testing.assert_allclose(obs[23:], by_hand, atol=1e-5)
