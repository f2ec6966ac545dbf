"""The shared config checks (envs/validation.py) on the values a user may type: strings, bools,
numpy scalars, infinities."""

import numpy as np
import pytest

import envs
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
