"""envs.physics.mjx_step: MuJoCo's step traced once per MJX model, reused by every env step traced after."""

import collections

import jax
from mujoco import mjx

import envs
from envs import fast_mjx, physics


def test_a_second_setting_of_the_same_robot_reuses_mujocos_traced_step(monkeypatch):
    """Two UR5e reach-avoid envs that differ in their obstacle radius (one MJX model, shared): tracing both steps
    traces `mjx.step` once."""
    traced, step = [], mjx.step

    def counting_step(model, data):
        traced.append(1)
        return step(model, data)

    monkeypatch.setattr(physics, "_STEPS", collections.OrderedDict())
    monkeypatch.setattr(physics.mjx, "step", counting_step)
    for radius in (0.05, 0.1):
        env = envs.make("ur5e-reach-avoid", backend="mjx", obstacle_radius=radius, substeps=1)
        state = jax.eval_shape(env.reset, jax.random.PRNGKey(0))
        jax.make_jaxpr(env.step)(state, jax.numpy.zeros(env.action_size))
    assert len(traced) == 1


def test_the_replacements_get_a_step_of_their_own():
    """A step traced with envs.fast_mjx's replacements is not reused without them (nor the other way round)."""
    model = envs.make("ur5e-reach", backend="mjx").robot.mjx_model
    plain = physics.mjx_step(model)
    with fast_mjx.fast_mjx(True):
        replaced = physics.mjx_step(model)
    assert replaced is not plain
