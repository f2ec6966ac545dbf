"""The reach-avoid obstacle options' configuration (defaults as the paper's, bad values refused naming the field)
and the obstacle trajectories, pure functions of time, against hand-computed positions and their bounds."""

import dataclasses
import typing

import jax
import jax.numpy as jnp
import numpy as np
import pytest

import envs
from envs import obstacles
from obstacle_envs import reflect_by_hand


# ------------------------------------------------------------------------------------------------
# Config


def test_defaults_are_the_paper_and_motion_names_match_the_registry():
    cfg = envs.default_config("ur5e-reach-avoid")
    assert (cfg.num_obstacles, cfg.obstacle_radius_range, cfg.obstacle_motion) == (1, None, "static")
    assert (cfg.joint_noise_std, cfg.obstacle_noise_std, cfg.action_latency) == (0.0, 0.0, 0)
    assert cfg.radius_bounds == (cfg.obstacle_radius, cfg.obstacle_radius)
    hint = typing.get_type_hints(type(cfg))["obstacle_motion"]
    assert typing.get_args(hint) == tuple(obstacles.MOTIONS)


@pytest.mark.parametrize("options, field, allowed", [
    (dict(num_obstacles=0), "num_obstacles", r"integer in \[1, 8\]"),
    (dict(num_obstacles=9), "num_obstacles", r"integer in \[1, 8\]"),
    (dict(num_obstacles=2.0), "num_obstacles", r"integer in \[1, 8\]"),
    (dict(obstacle_radius_range=(0.15, 0.05)), "obstacle_radius_range", "min <= max"),
    (dict(obstacle_radius_range=(0.0, 0.1)), "obstacle_radius_range", "> 0"),
    (dict(obstacle_radius_range=(0.05,)), "obstacle_radius_range", r"\(min, max\)"),
    (dict(obstacle_radius_range=(0.05, 5.0)), "obstacle_radius_range", "reach"),
    (dict(obstacle_motion="circle"), "obstacle_motion", "'static', 'linear', 'sinusoid'"),
    (dict(obstacle_speed_range=(-0.1, 0.2)), "obstacle_speed_range", ">= 0"),
    (dict(obstacle_speed_range=(0.3, 0.1)), "obstacle_speed_range", "min <= max"),
    (dict(obstacle_speed_range=(0.1, float("inf"))), "obstacle_speed_range", "finite"),
    (dict(obstacle_period=0.0), "obstacle_period", "> 0"),
    (dict(joint_noise_std=-0.01), "joint_noise_std", ">= 0"),
    (dict(obstacle_noise_std=-1.0), "obstacle_noise_std", ">= 0"),
    (dict(joint_noise_std=0.01, observation=("ee_pos", "target_pos")), "joint_noise_std", "joint_pos, joint_sin_cos"),
    (dict(obstacle_noise_std=0.01, observation=("joint_pos", "obstacle_vel")), "obstacle_noise_std",
     "obstacle_pos, link_obstacle_dist"),
    (dict(obstacle_lookahead=()), "obstacle_lookahead", "a tuple of 1 to 8 horizons"),
    (dict(joint_noise_model="kalman"), "joint_noise_model", "'angles', 'encoders'"),
    (dict(joint_noise_model="encoders"), "joint_noise_model", "'angles' unless joint_noise_std > 0"),
    (dict(joint_noise_model="encoders", joint_noise_std=0.01, observation=("joint_pos", "ee_vel")), "joint_noise_model",
     "'angles' while ee_vel is observed"),
    (dict(action_latency=2), "action_latency", r"integer in \[0, 1\]"),
    (dict(action_latency=-1), "action_latency", r"integer in \[0, 1\]"),
    (dict(action_latency=True), "action_latency", r"integer in \[0, 1\]"),
])
def test_bad_values_are_refused_naming_the_field(options, field, allowed):
    value = repr(next(iter(options.values())))
    with pytest.raises(ValueError, match=rf"^{field}={value.replace('(', '[(]').replace(')', '[)]')} is invalid: "
                                         rf"allowed (is|are).*{allowed}"):
        envs.make_config("ur5e-reach-avoid", **options)


@pytest.mark.parametrize("horizons, message", [
    ((0.5, 0.0), r"^obstacle_lookahead\[1\]=0.0 is invalid: allowed is a finite number > 0"),
    ((float("nan"),), r"^obstacle_lookahead\[0\]=nan is invalid: allowed is a finite number > 0"),
    ((0.5,) * 9, r"^obstacle_lookahead=.* is invalid: allowed is a tuple of 1 to 8 horizons"),
])
def test_bad_lookahead_horizons_are_refused_naming_the_horizon(horizons, message):
    with pytest.raises(ValueError, match=message):
        envs.make_config("ur5e-reach-avoid", obstacle_lookahead=horizons)


def test_constant_observation_parts_are_named_with_their_setting():
    """The parts a static or fixed-size config holds at one value in every episode: what a policy trained there
    never saw change (agents.evaluation.unseen_constants)."""
    paper = envs.registry.default_config("ur5e-reach-avoid")
    assert paper.constant_observations() == {"obstacle_vel": "obstacle_motion='static'",
                                             "obstacle_size": "obstacle radius 0.1 m",
                                             "obstacle_radius": "obstacle radius 0.1 m"}
    moving = dataclasses.replace(paper, obstacle_motion="sinusoid", obstacle_radius_range=(0.07, 0.07))
    assert moving.constant_observations() == {"obstacle_size": "obstacle radius 0.07 m",
                                              "obstacle_radius": "obstacle radius 0.07 m"}
    assert dataclasses.replace(moving, obstacle_radius_range=(0.05, 0.1)).constant_observations() == {}


def test_reach_task_has_noise_and_latency_but_no_obstacle_options():
    envs.make_config("ur5e-reach", joint_noise_std=0.01, action_latency=1)
    with pytest.raises(ValueError, match="num_obstacles"):
        envs.make_config("ur5e-reach", num_obstacles=2)


# ------------------------------------------------------------------------------------------------
# Trajectories (pure functions of time)


def test_linear_motion_bounces_as_computed_by_hand():
    params = {"center": jnp.array([[0.5, 0.0, -0.2]]), "velocity": jnp.array([[0.2, 0.0, -0.1]])}
    state = lambda t: [np.asarray(a)[0] for a in obstacles.MOTIONS["linear"].state(params, t, 2.0, 0.6)]  # noqa: E731
    # x: 0.5 -> wall at 0.6 (t = 0.5 s) -> back; z: -0.2 -> wall at -0.6 (t = 4 s) -> back.
    np.testing.assert_allclose(state(0.25)[0], [0.55, 0.0, -0.225], atol=1e-6)
    pos, vel = state(1.0)
    np.testing.assert_allclose(pos, [0.5, 0.0, -0.3], atol=1e-6)
    np.testing.assert_allclose(vel, [-0.2, 0.0, -0.1], atol=1e-6)
    pos, vel = state(7.0)  # x: 0.6 at 0.5 s, -0.6 at 6.5 s, -0.5 at 7 s; z: -0.6 at 4 s, -0.3 at 7 s
    np.testing.assert_allclose(pos, [-0.5, 0.0, -0.3], atol=1e-5)
    np.testing.assert_allclose(vel, [0.2, 0.0, 0.1], atol=1e-6)


@pytest.mark.parametrize("motion", ["linear", "sinusoid"])
def test_trajectories_stay_in_the_cube_over_a_long_horizon(motion):
    region, period, n = 0.6, 2.0, 256
    k_center, k_speed, k_motion = jax.random.split(jax.random.PRNGKey(0), 3)
    centers = jax.random.uniform(k_center, (n, 3), minval=-region, maxval=region).at[:16].set(0.0)
    speeds = jax.random.uniform(k_speed, (n,), minval=0.05, maxval=0.5)
    m = obstacles.MOTIONS[motion]
    params = m.sample(k_motion, centers, speeds, period, region)
    times = jnp.arange(0.0, 600.0, 0.01)  # 10 minutes of episode time, 60,000 points
    pos, vel = jax.vmap(lambda t: m.state(params, t, period, region))(times)
    pos, vel = np.asarray(pos), np.asarray(vel)
    assert np.abs(pos).max() <= region + 1e-5
    start = centers if motion == "linear" else centers + params["amplitude"] * jnp.sin(params["phase"])[:, None]
    np.testing.assert_allclose(pos[0], start, atol=1e-6)
    speed = np.linalg.norm(vel, axis=-1)
    if motion == "linear":
        np.testing.assert_allclose(speed, np.broadcast_to(speeds, speed.shape), rtol=1e-5)  # bounces keep the speed
        assert (np.abs(pos).max(axis=(0, 2)) > region - 0.01).mean() > 0.95, "obstacles should reach the walls"
        # Against the bounce-by-bounce unfolding of the straight path, at a few times (float32: the error of
        # c + v t grows with t, 5e-4 m after 10 minutes; an episode lasts seconds).
        for t in (3.0, 77.7):
            free = np.asarray(centers + params["velocity"] * t)
            np.testing.assert_allclose(pos[int(round(t / 0.01))], reflect_by_hand(free, -region, region), atol=2e-4)
    else:
        np.testing.assert_allclose(pos[200:400], pos[:200], atol=1e-4)  # period 2 s = 200 samples
        assert speed.max(axis=0)[:16] == pytest.approx(np.asarray(speeds[:16]), rel=1e-3)  # centred: the full amplitude
        assert (speed.max(axis=0) <= np.asarray(speeds) * (1 + 1e-4)).all()  # capped ones are slower
        assert (np.ptp(pos, axis=0).max(axis=-1) > 0.01).mean() > 0.9, "obstacles should move"
    # Velocity is the time derivative of position (central differences over the first minute, away from
    # bounces: within 0.5 m/s * 0.01 s of a wall a bounce may fall between the samples).
    pos, vel = pos[:6000], vel[:6000]
    fd = (pos[2:] - pos[:-2]) / 0.02
    smooth = np.all(np.abs(pos[1:-1]) < region - 0.006, axis=-1)
    assert smooth.mean() > 0.5
    np.testing.assert_allclose(fd[smooth], vel[1:-1][smooth], atol=1e-3)
