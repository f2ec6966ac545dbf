"""The arm environments' options: observation parts (against numpy and CPU MuJoCo), bad options and names refused
at make, frozen documented configs, steps refused for a foreign action or state, and resets that fall back."""

import dataclasses
import re

import jax
import jax.numpy as jnp
import mujoco
import numpy as np
import pytest

import envs
from agents import driver, presets
from envs import validation


def test_observation_parts_sizes():
    env = envs.make("panda-reach-avoid", observation=("joint_pos", "joint_vel", "joint_acc", "ee_pos", "ee_vel",
                                                      "target_pos", "ee_to_target", "prev_action", "obstacle_pos",
                                                      "obstacle_size", "link_obstacle_dist"))
    nlinks = len(env.robot.link_bodies)
    assert env.observation_size == 7 * 4 + 3 * 4 + 3 + 3 + nlinks
    state = env.reset(jax.random.PRNGKey(0))
    assert state.obs.shape == (env.observation_size,)


def test_joint_sin_cos_and_self_distance_observations():
    """The two parts that are not in the paper, against numpy and CPU MuJoCo's geom distances."""
    env = envs.make("ur5e-reach", observation=("joint_pos", "joint_sin_cos", "self_dist"))
    pairs = env.robot.self_pairs
    assert env.observation_size == 6 + 12 + len(pairs)
    assert len(pairs) == 18
    state = env.reset(jax.random.PRNGKey(3))
    obs, q = np.asarray(state.obs), np.asarray(state.pipeline_state.qpos)
    np.testing.assert_allclose(obs[:6], q)
    np.testing.assert_allclose(obs[6:12], np.sin(q), atol=1e-6)
    np.testing.assert_allclose(obs[12:18], np.cos(q), atol=1e-6)
    m = env.robot.mj_model
    d = mujoco.MjData(m)
    d.qpos[:] = q
    mujoco.mj_kinematics(m, d)
    expected = [mujoco.mj_geomDistance(m, d, int(g1), int(g2), 10.0, None) for g1, g2 in pairs]
    np.testing.assert_allclose(obs[18:], expected, atol=2e-5)
    assert obs[18:].min() > 0  # a reset pose is collision-free


@pytest.mark.parametrize("options, field", [
    (dict(workspace="kitchen"), "workspace"),
    (dict(action="torque"), "action"),
    (dict(reward="shaped"), "reward"),
    (dict(target_radius=-0.01), "target_radius"),
    (dict(target_radius=0.0), "target_radius"),
    (dict(episode_length=0), "episode_length"),
    (dict(substeps=2.5), "substeps"),
    (dict(observation=("joint_pos", "obstacle_pos")), "obstacle_pos"),
    (dict(observation=("joint_pos", "wrist_cam")), "wrist_cam"),
    (dict(observation="joint_pos"), "observation"),
    (dict(observation=("ee_pos", "ee_pos")), "observation"),
    (dict(workspace="pandagym"), "target_sampling"),
    (dict(obstacle_radius=0.2), "obstacle_radius"),
    (dict(w_dist=float("nan")), "w_dist"),
    (dict(relative_to="ctrl"), "relative_to"),
    (dict(integrator="rk4"), "integrator"),
])
def test_bad_options_fail_at_make(options, field):
    with pytest.raises(ValueError, match=field):
        envs.make("ur5e-reach", **options)


def test_bad_reach_avoid_options_and_names():
    with pytest.raises(ValueError, match="obstacle_radius"):
        envs.make("panda-reach-avoid", obstacle_radius=0.0)
    with pytest.raises(ValueError, match="link_distance"):
        envs.make("panda-reach-avoid", link_distance="centre")
    with pytest.raises(ValueError, match="ur5e-reach-avoid"):  # the message lists the valid names
        envs.make("ur5e-reach-avoidance")
    assert {"ur5e-reach", "panda-reach", "ur5e-reach-avoid", "panda-reach-avoid"} <= set(envs.names())


def test_configs_are_frozen_and_documented():
    for name in ("ur5e-reach", "panda-reach", "ur5e-reach-avoid", "panda-reach-avoid"):
        config = envs.default_config(name)
        with pytest.raises(dataclasses.FrozenInstanceError):
            config.workspace = "front"
    assert envs.default_config("ur5e-reach").target_radius == 0.01
    assert envs.default_config("ur5e-reach-avoid").target_radius == 0.02
    assert envs.default_config("ur5e-reach-avoid").reward == "semi_sparse"
    assert envs.default_config("ur5e-reach").reward == "dense"


@pytest.mark.parametrize("action, error, named", [
    ([0.0] * 6, TypeError, "action of type list is invalid for one ur5e env"),
    ("abc", TypeError, "action of type str is invalid"),
    (np.array([None] * 6, dtype=object), TypeError, "action of dtype object is invalid"),
])
def test_step_refuses_an_action_that_is_not_a_numeric_array(action, error, named):
    env = envs.make("ur5e-reach", backend="mujoco")
    state = env.reset(jax.random.PRNGKey(0))
    with pytest.raises(error, match=re.escape(named)):
        env.step(state, action)


def test_step_refuses_a_state_that_is_not_this_envs():
    ur5e = envs.make("ur5e-reach", backend="mujoco")
    panda_state = envs.make("panda-reach", backend="mujoco").reset(jax.random.PRNGKey(0))
    with pytest.raises(ValueError, match=re.escape("state with joint positions of shape (7,) is invalid for one ur5e")):
        ur5e.step(panda_state, jnp.zeros(6))
    with pytest.raises(TypeError, match="state of type NoneType is invalid for one ur5e env"):
        ur5e.step(None, jnp.zeros(6))


def test_resets_that_mostly_fall_back_are_refused_naming_the_changed_options():
    config, default = envs.make_config("ur5e-reach-avoid", obstacle_radius=0.7), envs.default_config("ur5e-reach-avoid")
    fallback = np.array([1.0] * 5 + [0.0] * 11)  # 5 of 16: 31 %
    with pytest.raises(ValueError, match=re.escape("with obstacle_radius=0.7: 31% of 16 resets found no valid start")):
        validation.resets_succeed("ur5e-reach-avoid", config, default, fallback)


def test_resets_that_fall_back_at_most_a_quarter_of_the_time_pass():
    config = envs.make_config("ur5e-reach-avoid", obstacle_radius=0.7)
    validation.resets_succeed("ur5e-reach-avoid", config, config, np.array([1.0] * 4 + [0.0] * 12))  # 25 %: no error


def test_training_with_options_whose_resets_fail_is_refused_before_anything_is_kept(tmp_path):
    cfg = presets.make_config("ur5e-reach-ppo-cpu", num_timesteps=1280, eval_envs=0, tensorboard=False, progress=False)
    env = envs.make_config("ur5e-reach-avoid", cfg.env, obstacle_radius=0.8, substeps=2, sampling_candidates=4,
                           episode_length=20)
    cfg = dataclasses.replace(cfg, env_name="ur5e-reach-avoid", env=env, logdir=str(tmp_path / "run"))
    with pytest.raises(ValueError, match=r"obstacle_radius=0.8: \d+% of 16 resets found no valid start"):
        driver.train(cfg)
    assert not (tmp_path / "run").exists()


def test_from_config_refuses_another_envs_config_class():
    with pytest.raises(TypeError, match=re.escape("config of type ReachAvoidConfig is invalid for env 'ur5e-reach': "
                                                  "allowed is ReachConfig")):
        envs.from_config("ur5e-reach", envs.make_config("ur5e-reach-avoid"))
