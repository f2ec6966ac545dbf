"""benchmarks/obstacle_paths.py: the first contact of moving obstacles with a standing arm, against CPU MuJoCo's
distances step by step; and the sampler's promise that no path runs into the geoms no joint moves."""

import jax
import jax.numpy as jnp
import numpy as np
import pytest

import envs
from benchmarks import obstacle_paths
from mujoco_reference import obstacle_contacts, obstacles_model

FAST = dict(num_obstacles=3, obstacle_motion="linear", obstacle_radius_range=(0.05, 0.1),
            obstacle_speed_range=(1.0, 2.0), episode_length=40)
"""Fast obstacles, short episodes (1.6 s): some episodes hit an arm standing still, some do not."""


def test_first_contacts_match_mujoco_step_by_step():
    env = envs.make("ur5e-reach-avoid", **FAST)
    robot, n = env.robot, 6
    states = jax.jit(jax.vmap(env.reset))(jax.random.split(jax.random.PRNGKey(5), n))  # 2 of these 6 hit a standing arm
    data = states.pipeline_state
    ours = np.asarray(jax.vmap(lambda i, x, m: obstacle_paths.first_contacts(env, i, x, m, robot.robot_geoms))(
        states.info, data.geom_xpos, data.geom_xmat))
    path = jax.vmap(lambda i, k: env.task_at(i, k)["obstacle_pos"], (None, 0))  # one episode's, per physics step
    steps = np.arange(env.config.episode_length + 1) * env.config.substeps
    positions = np.asarray(jax.jit(jax.vmap(path, (0, None)))(states.info, steps))  # (episode, control step, 9)
    expected = []
    for e in range(n):
        info = jax.tree.map(lambda x: x[e], states.info)
        model = obstacles_model(robot, np.asarray(info["obstacle_radius"]), every_geom=True)
        first = -1
        for step in range(env.config.episode_length + 1):
            centers = positions[e, step].reshape(3, 3)
            _, distances, _ = obstacle_contacts(model, np.asarray(data.qpos[e]), centers)
            if distances.min() < 0:
                first = step
                break
        expected.append(first)
    assert sum(f >= 0 for f in expected) >= 2  # the test sees contacts ...
    assert sum(f < 0 for f in expected) >= 2  # ... and episodes without
    np.testing.assert_array_equal(ours, expected)


def test_no_sampled_path_runs_into_the_geoms_no_joint_moves():
    env = envs.make("ur5e-reach-avoid", **FAST)
    result = obstacle_paths.measure(env, 12, seed=2)
    assert result["fixed_geoms"] == ["base", "shoulder"]
    assert result["fallback_share"] == 0.0  # every start drawn, so every path was held to the check
    assert result["fixed_share"] == 0.0  # 4 of these 12 ran into the base or the first link before paths were checked


def test_static_obstacles_are_refused_naming_the_field():
    env = envs.make("ur5e-reach-avoid", num_obstacles=3, substeps=2)
    with pytest.raises(ValueError, match="obstacle_motion='static'"):
        obstacle_paths.measure(env, 4)


def test_sampled_paths_stay_clear_of_the_fixed_geoms_at_every_physics_substep():
    """The sampler reads each path every few control steps with a margin; read at every substep, none touches."""
    env = envs.make("ur5e-reach-avoid", **FAST)
    robot, cfg = env.robot, env.config
    states = jax.jit(jax.vmap(env.reset))(jax.random.split(jax.random.PRNGKey(3), 12))
    data = states.pipeline_state

    def closest(info, geom_xpos, geom_xmat):
        def at(k):
            centers, radii = env.obstacles(env.task_at(info, k))
            return jnp.min(robot.obstacle_distances(geom_xpos, geom_xmat, centers, radii[:, None], robot.fixed_geoms))
        return jnp.min(jax.vmap(at)(jnp.arange(cfg.episode_length * cfg.substeps + 1)))

    clearance = np.asarray(jax.jit(jax.vmap(closest))(states.info, data.geom_xpos, data.geom_xmat))
    drawn = np.asarray(states.metrics["reset_fallback"]) == 0  # a start found among the candidates (not a fallback)
    assert drawn.sum() >= 9  # most found one (these fast obstacles need a 0.2 m margin)
    assert clearance[drawn].min() > 0


def test_a_path_through_the_base_between_two_readings_is_rejected():
    """At 2 m/s (the range's top: margin 0.5 * 2 * 5 * 0.04 = 0.2 m) an obstacle of radius 0.05 that crosses the base
    sphere's centre (radius 0.075) at 2.5 control steps is 0.2 m from it at the readings of steps 0 and 5, clear by
    0.075 m: only the margin rejects it. The same path 0.5 m lower is kept."""
    env = envs.make("ur5e-reach-avoid", **FAST)
    robot = env.robot
    kin = robot.kinematics(jnp.zeros(robot.nq))
    base = np.asarray(kin.geom_xpos)[int(robot.mj_model.geom("base").id)]
    velocity = np.array([2.0, 0.0, 0.0])
    start = base - velocity * 2.5 * env.dt
    centers = np.stack([start, start - [0.0, 0.0, 0.5]])[:, None]  # (obstacle, candidate, 3)
    params = {"center": jnp.asarray(centers, jnp.float32),
              "velocity": jnp.asarray(np.broadcast_to(velocity, centers.shape), jnp.float32)}
    clear = np.asarray(env.path_clear_of_fixed_geoms(params, jnp.full((2, 1), 0.05), kin))
    assert not clear[0, 0]
    assert clear[1, 0]

