"""envs.arm.ArmEnv.observation_part_sizes: traced once per process for envs built alike, and again for anything
that decides the sizes (the config, the env's observation code)."""

import dataclasses

import jax
import jax.numpy as jnp
import pytest

import envs
from envs import arm
from envs.cache import LRU
from envs.tasks.reach import Reach

OBS = ("joint_pos", "ee_pos")


@pytest.fixture
def resets(monkeypatch):
    """Counts traced resets, starting from an empty memo."""
    monkeypatch.setattr(arm, "_PART_SIZES", LRU(8))
    count, reset = [], arm.ArmEnv._reset

    def counting_reset(self, rng):
        count.append(1)
        return reset(self, rng)

    monkeypatch.setattr(arm.ArmEnv, "_reset", counting_reset)
    return count


def _sizes(**overrides):
    return envs.make("ur5e-reach", backend="mujoco", **overrides).unwrapped.observation_part_sizes


def test_envs_built_alike_trace_one_reset(resets):
    _sizes(observation=OBS)
    _sizes(observation=OBS)
    assert len(resets) == 1


def test_another_config_gets_its_own_sizes(resets):
    _sizes()
    assert _sizes(observation=OBS) == {"joint_pos": 6, "ee_pos": 3}


def test_observation_code_changed_in_place_gets_new_sizes(resets, monkeypatch):
    _sizes(observation=OBS)
    parts = Reach.observation_parts
    monkeypatch.setattr(Reach, "observation_parts", lambda self, data, xpos, ee, info: {
        **parts(self, data, xpos, ee, info), "joint_pos": lambda: jnp.concatenate([data.qpos, data.qpos])})
    assert _sizes(observation=OBS)["joint_pos"] == 12


def test_a_config_holding_a_traced_value_is_sized_without_the_memo(resets):
    base = envs.make("ur5e-reach-avoid", backend="mujoco", observation=OBS).unwrapped

    def size(radius):
        env = base.with_config(dataclasses.replace(base.config, obstacle_radius=radius))
        return jnp.zeros(env.observation_size)

    assert jax.eval_shape(size, 0.1).shape == (9,)
