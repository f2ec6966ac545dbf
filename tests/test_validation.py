"""The shared config checks (envs/validation.py) on the values a user may type: strings, bools,
numpy scalars, infinities."""

import dataclasses

import numpy as np
import pytest

import envs
import train
from agents.config import validate
from agents.presets import PRESETS, make_config
from envs import validation


@pytest.mark.parametrize("options, message", [
    (dict(dim="2"), r"dim='2' is invalid: allowed is an integer >= 1"),
    (dict(dim=2.5), r"dim=2.5 is invalid: allowed is an integer >= 1"),
    (dict(episode_length=2.5), r"episode_length=2.5 is invalid: allowed is an integer >= 1"),
    (dict(dt="0.1"), r"dt='0.1' is invalid: allowed is a finite number > 0"),
    (dict(goal_radius=float("inf")), r"goal_radius=inf is invalid: allowed is a finite number > 0"),
    (dict(alpha=True), r"alpha=True is invalid: allowed is a finite number > 0"),
])
def test_point_mass_rejects_values_of_the_wrong_kind(options, message):
    with pytest.raises(ValueError, match=message):
        envs.make_config("point-mass", **options).validate()


def test_numpy_scalars_count_as_numbers():
    config = envs.make_config("ur5e-reach-avoid", obstacle_radius=np.float32(0.1), episode_length=np.int64(50))
    config.validate()  # no error
    validation.integer("n", np.int32(3), 1)
    validation.in_range("x", np.float64(0.5), 0.0, 1.0)
    with pytest.raises(ValueError, match=r"x=nan is invalid: allowed is a number in \[0.0, 1.0\]"):
        validation.in_range("x", float("nan"), 0.0, 1.0)
    with pytest.raises(ValueError, match=r"n=np.int32\(0\) is invalid|n=0 is invalid"):
        validation.integer("n", np.int32(0), 1)


@pytest.mark.parametrize("name, options, message", [
    ("ur5e-reach-avoid", dict(obstacle_radius=1e6), r"obstacle_radius=1000000.0 is invalid: allowed is a number in "
                                                    r"\(0, 0.97\) \(below the ur5e's reach, m\)"),
    ("panda-reach-avoid", dict(obstacle_radius=0.945), r"obstacle_radius=0.945 is invalid: .*\(0, 0.945\)"),
    ("ur5e-reach", dict(target_radius=1e6), r"target_radius=1000000.0 is invalid: allowed is a number in \(0, 0.97\)"),
    ("ur5e-reach-avoid", dict(obstacle_region=1e6), r"obstacle_region=1000000.0 is invalid: allowed is a number in "
                                                    r"\(0, 1.94\] \(at most twice the ur5e's reach, m\)"),
    ("ur5e-reach", dict(action_scale=1e9), r"action_scale=1000000000.0 is invalid: allowed is a number in "
                                           r"\(0, 12.5664\] \(at most the ur5e's widest joint range, rad\)"),
    ("panda-reach", dict(action_scale=6.0), r"action_scale=6.0 is invalid: .*\(0, 5.79\d*\]"),
    ("ur5e-reach", dict(observation=["joint_pos", "ee_pos"]), r"observation=\['joint_pos', 'ee_pos'\] is invalid: "
                                                               r"allowed is a non-empty tuple"),
])
def test_arm_options_are_bounded_by_the_robot(name, options, message):
    """Absurd finite values used to train without an error (every episode ending at step 1)."""
    with pytest.raises(ValueError, match=message):
        envs.make_config(name, **options)
    with pytest.raises(ValueError, match=message):  # the env itself checks too
        envs.from_config(name, envs.registry.dataclasses.replace(envs.default_config(name), **options))


def test_bounds_leave_the_papers_values_alone():
    envs.make_config("ur5e-reach-avoid", obstacle_radius=0.3, obstacle_region=0.6, target_radius=0.05, action_scale=0.3)
    envs.make_config("panda-reach", action="absolute", action_scale=np.float32(0.2))


@pytest.mark.parametrize("name", [["ur5e-reach"], None, 3])
def test_env_name_of_the_wrong_kind_is_a_value_error(name):
    with pytest.raises(ValueError, match=r"env=.* is unknown: allowed are .*ur5e-reach"):
        envs.make(name)


# Values that fit Python but not the int32 / float32 that JAX computes in are refused where they are made.

def test_an_integer_beyond_int32_is_refused_naming_int32():
    with pytest.raises(ValueError, match=r"episode_length=2147483648 is invalid: allowed is an integer in "
                                         r"\[1, 2147483647\] \(int32"):
        envs.make_config("ur5e-reach", episode_length=2**31).validate()


def test_the_largest_int32_is_allowed():
    validation.integer("n", 2**31 - 1, 1)


def test_a_weight_beyond_float32_is_refused():
    with pytest.raises(ValueError, match=r"w_dist=1e\+308 is invalid: allowed is a finite number >= 0 \(at most 3.403e\+38"):
        envs.make_config("ur5e-reach", w_dist=1e308).validate()


def test_a_finite_number_beyond_float32_is_refused():
    with pytest.raises(ValueError, match=r"x=1e\+39 is invalid: allowed is a finite number"):
        validation.finite("x", 1e39)


def test_the_largest_float32_is_allowed():
    validation.finite("x", 3.4e38)


def test_a_run_longer_than_int32_updates_is_refused_before_anything_runs():
    config = make_config("point-mass-sac", num_timesteps=10**12)  # 16 env steps an update: 6.25e10 updates
    with pytest.raises(ValueError, match=r"num_timesteps=1000000000000 is invalid: allowed is at most "
                                         r"34,359,738,352 env steps \(2,147,483,647 updates of 16"):
        validate(config)


def test_a_seed_beyond_int32_is_refused():
    with pytest.raises(ValueError, match=r"seed=2147483648 is invalid"):
        validate(make_config("point-mass-ppo", seed=2**31))


def test_the_last_seed_of_several_must_fit_int32():
    with pytest.raises(ValueError, match=r"seed=2147483647 is invalid with seeds=2: allowed is seed <= 2147483646"):
        validate(make_config("point-mass-ppo", seed=2**31 - 1, seeds=2))


@pytest.mark.parametrize("name", ["../outside", "a/b", "..", ".hidden"])
def test_a_preset_name_that_would_leave_runs_is_refused(name):
    with pytest.raises(ValueError, match=r"preset=.* is invalid: allowed is a name of letters, digits"):
        validate(dataclasses.replace(make_config("point-mass-ppo"), preset=name))


@pytest.fixture
def validations(monkeypatch):
    """The outermost calls of the env configs' `validate` (ReachAvoidConfig's calls ReachConfig's: one call)."""
    calls, depth = [], [0]
    for cls in (envs.PointMassConfig, envs.ReachConfig, envs.ReachAvoidConfig):
        def counted(self, original=cls.__dict__["validate"]):
            if not depth[0]:
                calls.append(type(self).__name__)
            depth[0] += 1
            try:
                return original(self)
            finally:
                depth[0] -= 1
        monkeypatch.setattr(cls, "validate", counted)
    return calls


@pytest.mark.parametrize("name", ["point-mass", "ur5e-reach", "ur5e-reach-avoid"])
def test_envs_make_checks_the_config_once(validations, name):
    envs.make(name)
    assert len(validations) == 1


def test_an_env_built_from_a_checked_config_is_not_checked_again(validations):
    config = envs.make_config("ur5e-reach-avoid")
    validations.clear()
    envs.registry.build("ur5e-reach-avoid", config)
    assert validations == []


def test_the_training_cli_leaves_the_check_to_the_training_run(validations):
    train.parse(["point-mass-ppo", "--env.goal-radius", "0.05"])
    assert validations == []


def test_a_training_config_is_checked_once_by_validate(validations):
    validate(make_config("point-mass-ppo"))
    assert len(validations) == 1


@pytest.mark.parametrize("name", sorted(PRESETS))
def test_every_preset_is_a_valid_config(name):
    validate(make_config(name))  # a preset is made unchecked: this is its check
