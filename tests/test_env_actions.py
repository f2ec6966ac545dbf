"""The arm environments' actions: shapes refused at trace time, clipping to the joint ranges, relative steps (from
the joint positions or the last targets), and the integrator option against CPU MuJoCo."""

import re

import jax
import jax.numpy as jnp
import mujoco
import numpy as np
import pytest

import envs
from agents import baselines
from envs.robots.base import ASSETS


@pytest.mark.parametrize("name", ["ur5e-reach", "point-mass"])
def test_wrong_action_shapes_are_refused_at_trace_time(name):
    """Before the fix, (n,) or (n, 1) actions for n envs, and () or (1,) for one, were broadcast over every joint."""
    env = envs.make(name, **({} if name == "point-mass" else {"substeps": 2}))
    a = env.action_size
    one = jax.eval_shape(env.reset, jax.random.PRNGKey(0))
    for shape in ((), (1,), (a + 1,), (1, a)):
        with pytest.raises(ValueError, match=rf"action of shape {re.escape(str(shape))} is invalid for one .* env.*"
                                             rf"allowed is shape \({a},\)"):
            jax.eval_shape(env.step, one, jax.ShapeDtypeStruct(shape, jnp.float32))
    batched = envs.wrap(env)
    many = jax.eval_shape(batched.reset, jax.random.split(jax.random.PRNGKey(0), 4))
    for shape in ((4,), (4, 1), (4, a + 1), (3, a), (a,)):
        with pytest.raises(ValueError, match=rf"action of shape {re.escape(str(shape))} is invalid for a batch of 4 "
                                             rf"envs .*allowed is shape \(4, {a}\)"):
            jax.eval_shape(batched.step, many, jax.ShapeDtypeStruct(shape, jnp.float32))
    jax.eval_shape(batched.step, many, jax.ShapeDtypeStruct((4, a), jnp.float32))  # the right shape traces


def test_actions_clipped_to_joint_range():
    env = envs.make("panda-reach", action="absolute")
    low, high = env.robot.joint_low, env.robot.joint_high
    np.testing.assert_allclose(env.action_to_ctrl(jnp.full(7, 5.0), jnp.zeros(7)), high)
    np.testing.assert_allclose(env.action_to_ctrl(jnp.zeros(7), jnp.zeros(7)), (low + high) / 2, atol=1e-6)
    rel = envs.make("panda-reach")
    q = jnp.asarray(high - 0.05)
    np.testing.assert_allclose(rel.action_to_ctrl(jnp.ones(7), q), high)  # clipped at the limit
    assert rel.config.action_scale == 0.2
    np.testing.assert_allclose(rel.action_to_ctrl(-jnp.ones(7), q), high - 0.05 - 0.2, atol=1e-6)
    np.testing.assert_allclose(rel.action_to_ctrl(jnp.full(7, 0.5), q - 0.5), high - 0.55 + 0.1, atol=1e-6)


def test_a_relative_step_in_joint_ranges_moves_each_joint_by_its_share_of_its_range():
    """action_unit="joint_range": UR5e ranges are 4 pi rad (the elbow 2 pi), so a step of 0.08 is 1.005 rad on five
    joints and 0.503 rad at the elbow; the default counts in radians, the same on every joint."""
    env = envs.make("ur5e-reach", action_unit="joint_range", action_scale=0.08)
    q = jnp.zeros(6)
    expected = 0.08 * np.array([4, 4, 2, 4, 4, 4]) * np.pi
    np.testing.assert_allclose(env.action_to_ctrl(jnp.ones(6), q), expected, rtol=1e-4)
    np.testing.assert_allclose(env.action_to_ctrl(-0.5 * jnp.ones(6), q), -0.5 * expected, rtol=1e-4)
    radians = envs.make("ur5e-reach", action_scale=0.08)
    np.testing.assert_allclose(radians.action_to_ctrl(jnp.ones(6), q), np.full(6, 0.08), rtol=1e-6)
    # the baselines' inverse (agents.baselines.joint_target_action) commands a target within one step exactly
    target = jnp.asarray(0.7 * expected)
    action = baselines.joint_target_action(env.config, env.robot, target, q)
    np.testing.assert_allclose(env.action_to_ctrl(action, q), target, rtol=1e-5)


def test_a_relative_step_in_joint_ranges_is_at_most_one_range():
    with pytest.raises(ValueError, match=r"action_scale=1.5 is invalid: allowed is a number in \(0, 1\] \(at most 1"):
        envs.make("ur5e-reach", action_unit="joint_range", action_scale=1.5)
    with pytest.raises(ValueError, match=r"action_unit='degree' is invalid: allowed are 'radian', 'joint_range'"):
        envs.make("ur5e-reach", action_unit="degree")


def _two_relative_steps(relative_to):
    """Start, first and second state of a native UR5e episode under two fixed relative actions."""
    env = envs.make("ur5e-reach", backend="mujoco", action_scale=0.5, relative_to=relative_to)
    first = env.reset(jax.random.PRNGKey(3))
    a1, a2 = jnp.full(6, 0.4), jnp.full(6, -0.1)
    second = env.step(first, a1)
    return env, first, second, env.step(second, a2)


def test_relative_to_target_adds_deltas_to_the_last_targets():
    """relative_to="target": two steps of 0.5 * 0.4 and 0.5 * -0.1 rad command start + 0.15 rad, wherever
    the servos got to in between (clipped to the joint range)."""
    env, start, _, last = _two_relative_steps("target")
    expected = np.clip(np.asarray(start.pipeline_state.qpos) + 0.15, env.robot.joint_low, env.robot.joint_high)
    np.testing.assert_allclose(last.pipeline_state.ctrl, expected, atol=1e-6)


def test_relative_to_position_adds_deltas_to_the_joint_positions():
    """The paper's reading: the second target is the joint positions after the first step - 0.05 rad."""
    env, _, middle, last = _two_relative_steps("position")
    expected = np.clip(np.asarray(middle.pipeline_state.qpos) - 0.05, env.robot.joint_low, env.robot.joint_high)
    np.testing.assert_allclose(last.pipeline_state.ctrl, expected, atol=1e-6)


def test_zero_relative_action_holds_the_targets_only_with_relative_to_target():
    """Gravity sags the arm under a position servo: re-targeting the sagged pose (the paper's reading) lets
    the targets drift, re-using the last targets keeps them."""
    drift = {}
    for relative_to in ("position", "target"):
        env = envs.make("ur5e-reach", backend="mujoco", relative_to=relative_to)
        start = state = env.reset(jax.random.PRNGKey(0))
        for _ in range(5):
            state = env.step(state, jnp.zeros(6))
        drift[relative_to] = np.abs(np.asarray(state.pipeline_state.ctrl - start.pipeline_state.qpos)).max()
    assert drift["target"] == 0.0
    assert drift["position"] > 1e-3


@pytest.mark.parametrize("robot, expected", [("ur5e", mujoco.mjtIntegrator.mjINT_IMPLICITFAST),
                                             ("panda", mujoco.mjtIntegrator.mjINT_EULER)])
def test_integrator_model_keeps_the_robot_files_integrator(robot, expected):
    assert envs.make(f"{robot}-reach").robot.mj_model.opt.integrator == expected


def test_integrator_euler_steps_as_mujoco_with_euler():
    """integrator="euler": 10 native env steps against `mj_step` on the model file with its integrator set
    to Euler (an independent MjModel), from the same start and with the controls the env applied."""
    env = envs.make("ur5e-reach", backend="mujoco", integrator="euler", action_scale=1.0)
    reference = mujoco.MjModel.from_xml_path(str(ASSETS / env.robot.xml_file))
    reference.opt.integrator = mujoco.mjtIntegrator.mjINT_EULER
    state = env.reset(jax.random.PRNGKey(1))
    data = mujoco.MjData(reference)
    data.qpos[:] = np.asarray(state.pipeline_state.qpos, np.float64)
    for t in range(10):
        state = env.step(state, jnp.full(6, 0.3 if t < 5 else -0.3))
        data.ctrl[:] = np.asarray(state.pipeline_state.ctrl, np.float64)
        mujoco.mj_step(reference, data, nstep=env.config.substeps)
        np.testing.assert_allclose(state.pipeline_state.qpos, data.qpos, atol=1e-4, err_msg=f"step {t}")


def test_integrators_step_differently():
    """The option reaches the physics: the same 5 steps end in different joint velocities."""
    qvel = {}
    for integrator in ("implicitfast", "euler"):
        env = envs.make("ur5e-reach", backend="mujoco", integrator=integrator, action_scale=1.0)
        state = env.reset(jax.random.PRNGKey(1))
        for _ in range(5):
            state = env.step(state, jnp.full(6, 0.3))
        qvel[integrator] = np.asarray(state.pipeline_state.qvel)
    assert np.abs(qvel["implicitfast"] - qvel["euler"]).max() > 1e-3
