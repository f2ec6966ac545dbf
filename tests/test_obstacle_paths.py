"""benchmarks/obstacle_paths.py: the first contact of moving obstacles with the geoms no joint moves, against CPU
MuJoCo's distances step by step."""

import jax
import numpy as np
import pytest

import envs
from benchmarks import obstacle_paths
from mujoco_reference import obstacle_contacts, obstacles_model

FAST = dict(num_obstacles=3, obstacle_motion="linear", obstacle_radius_range=(0.05, 0.1),
            obstacle_speed_range=(1.0, 2.0), episode_length=40)
"""Fast obstacles, short episodes (1.6 s): 4 of the 12 episodes of reset seed 2 meet the base or the first link."""


def test_first_contacts_match_mujoco_step_by_step():
    env = envs.make("ur5e-reach-avoid", **FAST)
    robot, n = env.robot, 12
    states = jax.vmap(env.reset)(jax.random.split(jax.random.PRNGKey(2), n))
    data = states.pipeline_state
    ours = np.asarray(jax.vmap(lambda i, x, m: obstacle_paths.first_contacts(env, i, x, m, robot.fixed_geoms))(
        states.info, data.geom_xpos, data.geom_xmat))
    fixed = [list(robot.robot_geoms).index(g) for g in robot.fixed_geoms]
    expected = []
    for e in range(n):
        info = jax.tree.map(lambda x: x[e], states.info)
        model = obstacles_model(robot, np.asarray(info["obstacle_radius"]), every_geom=True)
        first = -1
        for step in range(env.config.episode_length + 1):
            centers = np.asarray(env.task_at(info, step * env.config.substeps)["obstacle_pos"]).reshape(3, 3)
            _, distances, _ = obstacle_contacts(model, np.asarray(data.qpos[e]), centers)
            if distances[:, fixed].min() < 0:
                first = step
                break
        expected.append(first)
    assert sum(f >= 0 for f in expected) >= 2  # the test sees contacts ...
    assert sum(f < 0 for f in expected) >= 2  # ... and episodes without
    np.testing.assert_array_equal(ours, expected)


def test_measure_reports_the_shares_of_its_episodes():
    env = envs.make("ur5e-reach-avoid", **FAST)
    result = obstacle_paths.measure(env, 12, seed=2)
    assert result["fixed_geoms"] == ["base", "shoulder"]
    assert result["fixed_share"] * 12 == pytest.approx(round(result["fixed_share"] * 12))  # a share of 12 episodes
    assert result["standing_share"] >= result["fixed_share"]  # the fixed geoms are among a standing arm's


def test_static_obstacles_are_refused_naming_the_field():
    env = envs.make("ur5e-reach-avoid", num_obstacles=3, substeps=2)
    with pytest.raises(ValueError, match="obstacle_motion='static'"):
        obstacle_paths.measure(env, 4)
