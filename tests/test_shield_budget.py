"""tools/shield_budget.py: the shielded evaluations ordered by cost, the unshielded reference read from both report
formats, mismatched sweeps refused, the figure written."""

import json

import pytest

from tools import shield_budget


def _report(path, samples, horizon, reached, kind="shielded", eval_seeds=(7,), name="runs/a"):
    """eval.py's JSON report of one evaluation at one budget (only the fields the tool reads)."""
    evaluation = {"env_name": "ur5e-reach-avoid", "env_config": {"num_obstacles": 3}, "num_envs": 64,
                  "eval_seeds": list(eval_seeds),
                  "policy": {"kind": kind, "name": name, "planner": {"samples": samples, "horizon": horizon},
                             "model_steps_per_step": horizon + samples * horizon},
                  "summary": {"target_reached": {"mean": reached}, "obstacle_collision": {"mean": 0.01},
                              "self_collision": {"mean": 0.0}}}
    path.write_text(json.dumps({"evaluations": [evaluation]}))
    return str(path)


_RUN_EVAL = {"eval_envs": 64, "mean": {"episode/target_reached": 0.8, "episode/obstacle_collision": 0.047}}
"""A training run's eval.json (only the fields the tool reads)."""


@pytest.fixture
def sweep(tmp_path):
    """Three budgets given out of cost order: 16x8 (136 steps), 4x8 (40), 64x8 (520)."""
    return [_report(tmp_path / "b.json", 16, 8, 0.83), _report(tmp_path / "a.json", 4, 8, 0.82),
            _report(tmp_path / "c.json", 64, 8, 0.84)]


def test_the_budgets_are_ordered_by_their_cost(sweep):
    assert [row["model_steps_per_step"] for row in shield_budget.budget_rows(sweep)] == [40, 136, 520]


def test_an_unshielded_evaluation_is_refused(sweep, tmp_path):
    plain = _report(tmp_path / "plain.json", 16, 8, 0.8, kind="checkpoint")
    with pytest.raises(ValueError, match="evaluates a checkpoint policy: allowed are shielded evaluations"):
        shield_budget.budget_rows(sweep + [plain])


def test_other_episodes_are_refused(sweep, tmp_path):
    other = _report(tmp_path / "other.json", 32, 8, 0.8, eval_seeds=(8,))
    with pytest.raises(ValueError, match="differs from .* in eval_seeds"):
        shield_budget.budget_rows(sweep + [other])


def test_another_env_config_is_refused(sweep, tmp_path):
    other = tmp_path / "other.json"
    report = json.loads(open(_report(other, 32, 8, 0.8)).read())
    report["evaluations"][0]["env_config"] = {"num_obstacles": 1}
    other.write_text(json.dumps(report))
    with pytest.raises(ValueError, match="differs from .* in env_config"):
        shield_budget.budget_rows(sweep + [str(other)])


def test_another_policy_is_refused(sweep, tmp_path):
    other = _report(tmp_path / "other.json", 32, 8, 0.8, name="runs/b")
    with pytest.raises(ValueError, match="differs from .* in policy"):
        shield_budget.budget_rows(sweep + [other])


def test_the_unshielded_reach_is_read_from_an_eval_report(tmp_path):
    plain = _report(tmp_path / "plain.json", 16, 8, 0.805, kind="checkpoint")
    assert shield_budget.unshielded_percents(plain, 64)["target_reached"] == pytest.approx(80.5)


def test_the_unshielded_collisions_are_read_from_a_training_runs_eval_json(tmp_path):
    path = tmp_path / "eval.json"
    path.write_text(json.dumps(_RUN_EVAL))
    assert shield_budget.unshielded_percents(str(path), 64)["obstacle_collision"] == pytest.approx(4.7)


def test_an_unshielded_evaluation_of_other_episodes_is_refused(tmp_path):
    path = tmp_path / "eval.json"
    path.write_text(json.dumps(_RUN_EVAL))
    with pytest.raises(ValueError, match="evaluated 64 episodes: allowed is the shielded evaluations' 4096"):
        shield_budget.unshielded_percents(str(path), 4096)


def test_the_figure_is_written(sweep, tmp_path):
    run_eval = tmp_path / "eval.json"
    run_eval.write_text(json.dumps(_RUN_EVAL))
    out = tmp_path / "budget.png"
    shield_budget.main(sweep + ["--unshielded", str(run_eval), "--out", str(out)])
    assert out.read_bytes()[:4] == b"\x89PNG"
