"""The robot's MJX model is put on the device when first used, not when the robot is made (a config check builds
a robot and costs no transfer), and robots built alike share one put (eval.py builds its env twice)."""

from __future__ import annotations

import jax
import jax.numpy as jnp
import numpy as np
import pytest
from mujoco import mjx

import envs
from envs.robots import ROBOTS, base


@pytest.fixture
def puts(monkeypatch):
    """The number of `mjx.put_model` calls made so far (a list of one counter), from an empty shared store."""
    monkeypatch.setattr(base, "_SHARED", {})
    count = [0]
    original = mjx.put_model

    def counted(*args, **kwargs):
        count[0] += 1
        return original(*args, **kwargs)

    monkeypatch.setattr(mjx, "put_model", counted)
    return count


def test_a_config_check_and_a_robot_put_no_model(puts):
    base.bounds.cache_clear()
    envs.make_config("ur5e-reach", substeps=2, episode_length=5)
    ROBOTS["ur5e"]()
    assert puts[0] == 0


def test_envs_built_alike_share_one_put(puts):
    first = envs.make("ur5e-reach", substeps=2, episode_length=5, backend="mujoco")
    second = envs.make("ur5e-reach", substeps=2, episode_length=5, backend="mujoco")
    first.reset(jax.random.PRNGKey(0))
    second.reset(jax.random.PRNGKey(1))
    assert puts[0] == 1


def test_envs_built_alike_step_the_same_device_model(puts):
    first = envs.make("ur5e-reach", substeps=2, episode_length=5, backend="mujoco")
    second = envs.make("ur5e-reach", substeps=2, episode_length=5, backend="mujoco")
    assert first.robot.mjx_model is second.robot.mjx_model


def test_another_integrator_puts_its_own_model(puts):
    ROBOTS["ur5e"]().mjx_model
    ROBOTS["ur5e"](integrator="euler").mjx_model
    assert puts[0] == 2


def test_another_integrator_steps_with_it(puts):
    euler = ROBOTS["ur5e"](integrator="euler").mjx_model
    assert int(euler.opt.integrator) == 0  # mjINT_EULER


def test_a_model_first_asked_for_inside_jit_is_concrete(puts):
    robot = ROBOTS["ur5e"]()
    jax.jit(lambda x: x + jnp.sum(robot.mjx_model.body_pos))(0.0)
    assert not isinstance(robot.mjx_model.body_pos, jax.core.Tracer)


def test_a_model_first_asked_for_inside_jit_holds_the_models_values(puts):
    robot = ROBOTS["ur5e"]()
    traced = jax.jit(lambda x: x + jnp.sum(robot.mjx_model.body_pos))(0.0)
    assert float(traced) == pytest.approx(float(np.sum(robot.mj_model.body_pos)), rel=1e-6)


def test_put_on_device_follows_an_edited_mujoco_model(puts):
    robot = ROBOTS["panda"]()
    robot.mjx_model
    robot.mj_model.dof_damping[0] = 123.0
    robot.put_on_device()
    assert float(robot.mjx_model.dof_damping[0]) == pytest.approx(123.0)


def test_an_edited_robot_leaves_the_shared_model_alone(puts):
    edited = ROBOTS["panda"]()
    edited.mj_model.dof_damping[0] = 123.0
    edited.put_on_device()
    fresh = ROBOTS["panda"]()
    assert float(fresh.mjx_model.dof_damping[0]) == pytest.approx(float(fresh.mj_model.dof_damping[0]))


def test_an_edit_without_put_on_device_does_not_become_the_shared_model(puts):
    """An in-place edit reaches MJX through `put_on_device` only; the shared copy is put from a robot as built."""
    edited = ROBOTS["panda"]()
    default = float(edited.mj_model.dof_damping[0])
    edited.mj_model.dof_damping[0] = 123.0
    edited.mjx_model  # first use, no put_on_device: the shared copy is made here
    assert float(ROBOTS["panda"]().mjx_model.dof_damping[0]) == pytest.approx(default)
