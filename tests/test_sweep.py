"""agents/sweep.py: one evaluation program for many values of a traced env field, held to `evaluation.run`'s
program compiled per value (CPU, the shipped Panda reach-avoid policy, short episodes)."""

import dataclasses

import numpy as np
import pytest

import envs
from agents import evaluation, sweep

SHIPPED = "results/checkpoints/panda-reach-avoid-ppo"
RADII = (0.05, 0.1, 0.2)
"""0.05 and 0.1 m share a program; 0.2 m doubles the obstacle candidates (over 0.15 m), so it needs another."""
COMPARED = ("return", "distance", "obstacle_collision", "target_reached")


@pytest.fixture(scope="module")
def policy():
    return evaluation.checkpoint_policy(SHIPPED)


@pytest.fixture(scope="module")
def configs(policy):
    return [envs.make_config(policy.train_env_name, policy.train_env_config, obstacle_radius=r, episode_length=20,
                             substeps=4) for r in RADII]


@pytest.fixture(scope="module")
def swept(policy, configs):
    sweep._PROGRAMS.clear()
    return sweep.run(policy, policy.train_env_name, "obstacle_radius", configs, num_envs=16)


@pytest.fixture(scope="module")
def references(policy, configs):
    """`evaluation.run` per radius: a program compiled for each."""
    return [evaluation.run(policy, policy.train_env_name, config, num_envs=16) for config in configs]


@pytest.mark.parametrize("index", range(len(RADII)))
@pytest.mark.parametrize("metric", COMPARED)
def test_each_value_gives_the_numbers_of_its_own_program(swept, references, index, metric):
    np.testing.assert_allclose(swept[index].per_env[metric], references[index].per_env[metric], rtol=1e-6, atol=1e-6)


def test_the_value_reaches_the_program(swept):
    # 0.05 and 0.1 m run one program: had it kept the first value, their returns would be equal
    assert not np.allclose(swept[0].per_env["return"], swept[1].per_env["return"])


def test_values_that_shape_the_program_alike_share_one(swept):
    assert len(sweep._PROGRAMS) == 2


def test_each_program_is_traced_once(swept):
    assert [entry.traces for entry in sweep._PROGRAMS.values()] == [1, 1]


def test_a_later_call_reuses_the_program(policy, configs, swept):
    sweep.run(policy, policy.train_env_name, "obstacle_radius",
              [dataclasses.replace(configs[0], obstacle_radius=0.07)], num_envs=16)
    assert [entry.traces for entry in sweep._PROGRAMS.values()] == [1, 1]


def test_with_config_keeps_the_candidates_decided_at_construction(configs):
    env = envs.from_config("panda-reach-avoid", configs[1]).with_config(configs[2])
    assert env.candidates("obstacle") == 8


def test_a_large_obstacle_doubles_the_candidates(configs):
    assert envs.from_config("panda-reach-avoid", configs[2]).candidates("obstacle") == 16


def test_configs_differing_elsewhere_are_refused(policy, configs):
    other = dataclasses.replace(configs[1], target_radius=0.05)
    with pytest.raises(ValueError, match=r"configs differ in \['target_radius'\] besides field='obstacle_radius'"):
        sweep.run(policy, policy.train_env_name, "obstacle_radius", [configs[0], other], num_envs=4)


def test_a_field_not_traced_falls_back_to_a_program_per_value(policy, configs):
    config = dataclasses.replace(configs[1], target_radius=0.05)
    swept, = sweep.run(policy, policy.train_env_name, "target_radius", [config], num_envs=4)
    reference = evaluation.run(policy, policy.train_env_name, config, num_envs=4)
    np.testing.assert_array_equal(swept.per_env["return"], reference.per_env["return"])


def test_an_unknown_field_is_refused_by_name(policy, configs):
    with pytest.raises(ValueError, match=r"field='radius' is invalid: allowed are the fields of ReachAvoidConfig"):
        sweep.run(policy, policy.train_env_name, "radius", configs, num_envs=4)


def test_a_field_without_effect_is_refused(policy, configs):
    ranged = [dataclasses.replace(c, obstacle_radius_range=(0.05, 0.1)) for c in configs[:2]]
    with pytest.raises(ValueError, match=r"field='obstacle_radius' is invalid here: it has no effect"):
        sweep.run(policy, policy.train_env_name, "obstacle_radius", ranged, num_envs=4)


def test_with_config_refuses_another_field(configs):
    env = envs.from_config("panda-reach-avoid", configs[0])
    with pytest.raises(ValueError, match=r"differs in \['sampling_candidates'\] besides TRACED_FIELDS"):
        env.with_config(dataclasses.replace(configs[0], sampling_candidates=4))


def test_an_invalid_request_is_refused_before_evaluating(policy, configs):
    with pytest.raises(ValueError, match=r"num_envs=0 is invalid: allowed is an integer >= 1"):
        sweep.run(policy, policy.train_env_name, "obstacle_radius", configs, num_envs=0)


def test_every_traced_field_is_held_to_a_program_per_value_here():
    declared = set()
    for name in envs.names():
        declared |= set(getattr(type(envs.registry.make_config(name, None)), "TRACED_FIELDS", ()))
    assert declared == {"obstacle_radius"}  # the field compared above; a new one needs its own comparison
