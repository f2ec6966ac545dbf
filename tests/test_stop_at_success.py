"""train's `stop_at_success`: a run stops once every seed's training episodes reach the success rate, and is then
evaluated on fresh episodes; an impossible rate is refused by name."""

import csv
import json

import numpy as np
import pytest

from agents import config as agent_config, driver, presets

QUIET = dict(tensorboard=False, progress=False)
BUDGET = 150_000
"""The point-mass PPO preset's run; its seeds reach the target in ~99 % of evaluation episodes at its end
(tests/test_agents_learning.py), so a 0.8 success rate comes well before."""


@pytest.fixture(scope="module")
def stopped_run(tmp_path_factory):
    logdir = tmp_path_factory.mktemp("stop") / "run"
    config = presets.make_config("point-mass-ppo", num_timesteps=BUDGET, seeds=2, stop_at_success=0.8,
                                 log_every=5_000, eval_envs=64, logdir=str(logdir), **QUIET)
    return driver.train(config), logdir


def _rows(logdir):
    with open(logdir / "metrics.csv") as f:
        return list(csv.DictReader(f))


def test_the_run_stops_before_its_budget(stopped_run):
    result, _ = stopped_run
    assert result.env_steps < BUDGET


def test_a_stopped_run_counts_as_done(stopped_run):
    result, _ = stopped_run
    assert result.status == "done"


def test_the_last_logged_success_of_every_seed_reached_the_rate(stopped_run):
    _, logdir = stopped_run
    rows = _rows(logdir)
    last = max(int(r["env_steps"]) for r in rows)
    assert all(float(r["episode/target_reached"]) >= 0.8 for r in rows if int(r["env_steps"]) == last)


def test_no_earlier_log_had_every_seed_at_the_rate(stopped_run):
    """It stops at the first log where the rate is met, not later."""
    _, logdir = stopped_run
    rows = _rows(logdir)
    steps = sorted({int(r["env_steps"]) for r in rows})
    earlier = [min(float(r["episode/target_reached"]) for r in rows if int(r["env_steps"]) == s) for s in steps[:-1]]
    assert all(value < 0.8 for value in earlier)


def test_the_stopped_run_is_evaluated_at_the_step_it_stopped(stopped_run):
    result, logdir = stopped_run
    report = json.loads((logdir / "eval.json").read_text())
    assert report["env_steps"] == result.env_steps


def test_without_the_option_the_same_run_would_not_stop():
    assert not driver.succeeded(presets.make_config("point-mass-ppo"), {"episode/target_reached": np.array([1.0])})


def test_one_seed_below_the_rate_keeps_the_run_going():
    config = presets.make_config("point-mass-ppo", stop_at_success=0.8)
    assert not driver.succeeded(config, {"episode/target_reached": np.array([0.9, 0.7])})


@pytest.mark.parametrize("value", [-0.1, 1.5, float("nan")])
def test_an_impossible_rate_is_refused_naming_the_field(value):
    config = presets.make_config("point-mass-ppo", stop_at_success=value)
    with pytest.raises(ValueError, match="stop_at_success="):
        agent_config.validate(config)
