"""envs.physics.mjx_step: MuJoCo's step traced once per MJX model, reused by every env step traced after."""

import jax
import pytest
from mujoco import mjx

import envs
from envs import fast_mjx, physics
from envs.cache import LRU


def test_a_second_setting_of_the_same_robot_reuses_mujocos_traced_step(monkeypatch):
    """Two UR5e reach-avoid envs that differ in their obstacle radius (one MJX model, shared): tracing both steps
    traces `mjx.step` once."""
    traced, step = [], mjx.step

    def counting_step(model, data):
        traced.append(1)
        return step(model, data)

    monkeypatch.setattr(physics, "_STEPS", LRU(physics.STEP_CACHE_SIZE))
    monkeypatch.setattr(physics.mjx, "step", counting_step)
    for radius in (0.05, 0.1):
        env = envs.make("ur5e-reach-avoid", backend="mjx", obstacle_radius=radius, substeps=1)
        state = jax.eval_shape(env.reset, jax.random.PRNGKey(0))
        jax.make_jaxpr(env.step)(state, jax.numpy.zeros(env.action_size))
    assert len(traced) == 1


@pytest.fixture(scope="module")
def panda_steps():
    """The Panda's (6-step line search, factorised mass matrix) cached step without and with fast_mjx's
    replacements, both lowered outside any fast_mjx context, and the program text of each."""
    robot = envs.make("panda-reach", backend="mjx").robot
    plain = physics.mjx_step(robot.mjx_model)
    with fast_mjx.fast_mjx(True):
        replaced = physics.mjx_step(robot.mjx_model)
    return {name: step.lower(robot.data_template).as_text() for name, step in (("plain", plain), ("fast", replaced))}


def test_the_plain_step_factorises_with_the_library(panda_steps):
    assert "cholesky" in panda_steps["plain"]


def test_the_replaced_step_holds_the_replacements_wherever_it_is_traced(panda_steps):
    """Made inside fast_mjx(True) and traced after it closed: still the written-out factorisation."""
    assert "cholesky" not in panda_steps["fast"]
