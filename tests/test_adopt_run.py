"""tools.adopt_run: a finished train.py run recorded as a registered run's done part, only when it is that run
evaluated as the driver evaluates."""

import csv
import json
import os

import pytest

from agents.config import config_json
from tools import adopt_run
from tools import experiment_state as ex
from tools import experiment_tables as tables

NAME = "reach-avoid-reward/dense"  # a run no other registered run shares (its record folder is its own)
SEEDS = 5


def _run():
    (exp, (run,)), = ex.select([NAME])
    return exp, run


def _files(tmp_path, units=None, **changes):
    """An eval.py JSON of the run's final checkpoint (seeds listed out of order) and its metrics.csv."""
    _, run = _run()
    config = run.config("anywhere", first_seed=0, seeds=SEEDS)
    train = config_json(config)
    budget = run.budget()
    evaluation = {"policy": {"kind": "checkpoint", "env_steps": budget + 480, "train_config": train},
                  "env_name": config.env_name, "env_config": train["env"], "num_envs": config.eval_envs,
                  "eval_seeds": [config.eval_seed], "last_steps": config.eval_last_steps, "actions": "deterministic",
                  "units": units if units is not None else [
                      {"policy_seed": s, "metrics": {"target_reached": (80 + s) / 100, "self_collision": 0.03,
                                                     "obstacle_collision": 0.02, "distance": 0.07}}
                      for s in (3, 0, 4, 1, 2)]}
    for key, value in changes.items():
        evaluation[key] = value
    path = tmp_path / "eval.json"
    path.write_text(json.dumps({"command": "python eval.py ...", "device": "GPU (test)", "code": "abc1234",
                                "evaluations": [evaluation]}))
    metrics = tmp_path / "metrics.csv"
    with open(metrics, "w", newline="") as f:
        w = csv.writer(f)
        w.writerow(["env_steps", "seed", "steps_per_second", "wall_seconds", "episode/target_reached"])
        for steps in (budget // 2, budget + 480):
            for s in range(SEEDS):
                w.writerow([steps, s, 400000.0, 100.0, 0.5])
    return str(path), str(metrics)


def test_a_matching_run_is_recorded_as_the_done_part(tmp_path):
    out = tmp_path / "record"
    folder = adopt_run.adopt(NAME, *_files(tmp_path), timing=False, out=str(out))
    assert folder == str(out / "reach-avoid-reward" / "runs" / "dense" / "seeds-0-4")
    with open(os.path.join(folder, "eval.json")) as f:
        evaluated = json.load(f)
    # in seed order, under the driver's keys; the source named
    assert evaluated["per_seed"]["episode/target_reached"] == [0.8, 0.81, 0.82, 0.83, 0.84]
    assert evaluated["per_seed"]["episode/distance_last10"] == [0.07] * 5
    assert evaluated["mean"]["episode/target_reached"] == pytest.approx(0.82)
    assert evaluated["eval_envs"] == 4096 and evaluated["source"]["code"] == "abc1234"
    with open(os.path.join(folder, "metrics.csv")) as f:
        rows = list(csv.DictReader(f))
    assert len(rows) == 10 and {r["steps_per_second"] for r in rows} == {""} and rows[0]["episode/target_reached"] == "0.5"
    _, run = _run()
    state = ex.run_state(*_run(), str(tmp_path / "runs"), str(out))
    assert state.status == "done" and [p.name for p in state.done_parts] == ["seeds-0-4"]
    # without timings, the table's timing cells stay empty (not 0 s); the table names the source
    assert tables.timing_cell(state, "wall_clock") == "" == tables.timing_cell(state, "steps_per_second")
    assert tables.merged_evaluation(state)["sources"] == [str(tmp_path / "eval.json")]
    exp, run = _run()
    tables.build_default(exp, [state], str(out / "reach-avoid-reward"), code="abc1234")
    table = (out / "reach-avoid-reward" / "table.md").read_text()
    assert (f"recorded with `tools.adopt_run` from the `eval.py` evaluation of the final checkpoint: dense from "
            f"{tmp_path / 'eval.json'}.") in table
    assert "| 82.0 ± 1.4 % |" in table
    with pytest.raises(ValueError, match="exists: allowed is a run with no part recorded"):
        adopt_run.adopt(NAME, *_files(tmp_path), out=str(out))


def _edited(tmp_path, edit):
    """_files with `edit` applied to the evaluation."""
    path, metrics = _files(tmp_path)
    data = json.loads(open(path).read())
    edit(data["evaluations"][0])
    open(path, "w").write(json.dumps(data))
    return path, metrics


def _discount_changed(tmp_path):
    return _edited(tmp_path, lambda e: e["policy"]["train_config"]["algo"].update(discount=0.5))


def _short_metrics(tmp_path):
    path, metrics = _files(tmp_path)
    lines = open(metrics).read().splitlines()
    open(metrics, "w").write("\n".join(line for line in lines if not line.endswith(",3,400000.0,100.0,0.5")
                                       or line.startswith(str(_run()[1].budget() // 2))) + "\n")
    return path, metrics


@pytest.mark.parametrize("make, message", [
    (_discount_changed, r"evaluated a run that is not reach-avoid-reward/dense: algo.discount=0.\d+ differs"),
    (lambda t: _edited(t, lambda e: e["policy"]["train_config"].update(num_timesteps=300_000_000)),
     r"not reach-avoid-reward/dense: num_timesteps=300000000, the run has 192000000"),
    (lambda t: _edited(t, lambda e: e["policy"]["train_config"].update(seeds=3)), r"seeds=3, the run has 5"),
    (lambda t: _files(t, num_envs=1024), r"num_envs=1024 differs from the driver's 4096"),
    (lambda t: _files(t, actions="stochastic"), r"actions='stochastic' differs from the driver's 'deterministic'"),
    (lambda t: _edited(t, lambda e: e["env_config"].update(obstacle_radius=0.2)), r"env_config=.*obstacle_radius=0.2.* differs"),
    (lambda t: _files(t, units=[{"policy_seed": s, "metrics": {"target_reached": 0.8}} for s in range(4)]),
     r"evaluated seeds \[0, 1, 2, 3\]: allowed is every seed of the run, \[0, 1, 2, 3, 4\]"),
    (_short_metrics, r"seed 3 is logged to \d+ env steps: allowed are metrics of every seed up to the budget"),
])
def test_anything_else_is_refused_and_leaves_no_part(make, message, tmp_path):
    out = tmp_path / "record"
    with pytest.raises(ValueError, match=message):
        adopt_run.adopt(NAME, *make(tmp_path), out=str(out))
    assert not (out / "reach-avoid-reward" / "runs" / "dense" / "seeds-0-4").exists()
    with pytest.raises(ValueError, match="allowed is one experiment/run"):
        adopt_run.adopt("reach-avoid-reward", *_files(tmp_path), out=str(out))
