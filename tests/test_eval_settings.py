"""benchmarks/eval_settings.py: a sweep over one env field in one process, checked against `evaluation.run`."""

import dataclasses

import pytest

from agents import evaluation, sweep
from benchmarks import eval_settings
from tools import literal_or_text

SHIPPED = "results/checkpoints/panda-reach-avoid-ppo"


def _base():
    policy = evaluation.checkpoint_policy(SHIPPED)
    return policy.train_env_name, policy.train_env_config


def test_an_unknown_field_is_refused_by_name():
    with pytest.raises(ValueError, match=r"option 'radius' does not exist for env 'panda-reach-avoid'"):
        eval_settings.settings(*_base(), "radius", ["0.1"])


def test_a_value_of_the_wrong_type_is_refused_by_name():
    with pytest.raises(ValueError, match=r"episode_length=1.5 is invalid: allowed is an integer >= 1"):
        eval_settings.settings(*_base(), "episode_length", ["40", "1.5"])


def test_a_typed_value_is_parsed_as_a_literal():
    config = eval_settings.settings(*_base(), "gravity_compensation", ["True"])[0]
    assert config.gravity_compensation is True


def test_a_name_stays_text():
    assert literal_or_text("front") == "front"


@pytest.fixture(scope="module")
def rows():
    """Episodes of 1 step (no arm gets to its target) and of the trained 125, 8 episodes each, on the CPU."""
    rows, _ = eval_settings.evaluate(SHIPPED, "episode_length", ["1", "125"], num_envs=8, seeds=1, log=lambda line: None)
    return rows


def test_the_obstacle_radius_is_a_program_argument():
    assert sweep.traced(_base()[1], "obstacle_radius") is True


def test_the_episode_length_is_not_a_program_argument():
    assert sweep.traced(_base()[1], "episode_length") is False


def test_a_one_step_episode_reaches_nothing(rows):
    assert rows[0]["success"] == 0.0


def test_each_row_is_the_evaluation_of_its_setting(rows):
    policy = evaluation.checkpoint_policy(SHIPPED)
    config = dataclasses.replace(policy.train_env_config, episode_length=125)
    result = evaluation.run(policy, policy.train_env_name, config, 8, eval_seeds=[evaluation.DEFAULT_EVAL_SEED])
    assert rows[1]["success"] == result.units[0]["metrics"]["target_reached"]


def test_the_trained_setting_reaches_targets(rows):
    assert rows[1]["success"] > 0.5
