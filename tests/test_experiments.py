"""tools/experiments.py: every registered run builds a valid config (and its train.py command parses back to
it), the state listing and command list on a hand-made runs folder, the time-limit plan, and a two-run toy
experiment on the point mass that trains, resumes after an interruption and builds its table."""

import importlib.util
import json
import os
import time

import pytest

import train
from agents import driver
from agents.config import config_json
from tools import experiments as ex

TOY_RUN = dict(eval_envs=16, tensorboard=False, progress=False)
# point-mass-ppo trains 5,120 env steps per update: two updates per run. The runs differ in their seeds
# only, so they share one compiled program (the test takes a minute on a loaded 2-core CPU, not two).
TOY = ex.Experiment("toy", "point mass: two sets of seeds", "not in the paper", (
    ex.Run("a", "point-mass-ppo", dict(TOY_RUN), seeds=2, num_timesteps=10_240, paper=dict(target_reached=0.5)),
    ex.Run("b", "point-mass-ppo", {**TOY_RUN, "seed": 10}, seeds=2, num_timesteps=10_240),
), metrics=("target_reached", "distance", "wall_clock"), curves=("episode/target_reached",))


@pytest.mark.parametrize("name", sorted(ex.EXPERIMENTS))
def test_registered_runs_are_valid_and_their_commands_parse_back(name):
    exp = ex.EXPERIMENTS[name]
    ex.validate_experiment(exp)
    for run in exp.runs:
        logdir = os.path.join(ex.RUNS_DIR, name, run.name)
        assert train.parse(run.train_args(logdir)) == run.config(logdir), run.name


SEEDS = {"action-space": 5, "reward": 3, "joint-penalties": 3, "reach-observation": 3, "network-size": 3,
         "sac-workspaces": 3, "reach-avoid-reward": 5, "reach-avoid-observation": 3, "reach-avoid-front": 5,
         "obstacle-size-ur5e": 5, "sac-reach": 5}
"""5 seeds where the paper states numbers to compare (tables, results text), 3 for curve-only comparisons."""


def test_registry_covers_the_issue_with_its_seeds():
    assert {n: {r.seeds for r in e.runs} for n, e in ex.EXPERIMENTS.items()} == {n: {s} for n, s in SEEDS.items()}
    assert all(r.budget() > 0 for e in ex.EXPERIMENTS.values() for r in e.runs)


def test_bad_overrides_and_names_raise():
    with pytest.raises(ValueError, match="env.no_such_field"):
        ex.Run("x", "point-mass-ppo", {"env.no_such_field": 1}).config()
    with pytest.raises(ValueError, match="seeds and budget are Run fields"):
        ex.Run("x", "point-mass-ppo", {"seeds": 3}).config()
    with pytest.raises(ValueError, match="goal_radius"):
        ex.validate_experiment(ex.Experiment("bad", "", "", (ex.Run("x", "point-mass-ppo", {"env.goal_radius": -1.0}),)))
    with pytest.raises(ValueError, match="registered twice"):
        ex.register(TOY, {"toy": TOY})
    with pytest.raises(ValueError, match="run 'zzz' is not in experiment 'toy'"):
        ex.select(["toy/zzz"], {"toy": TOY})
    with pytest.raises(ValueError, match="experiment 'zzz' is unknown"):
        ex.select(["zzz"], {"toy": TOY})
    assert ex.cli_option("algo.policy_hidden_sizes", (64, 64)) == ["--algo.policy-hidden-sizes", "64", "64"]
    assert ex.cli_option("tensorboard", False) == ["--no-tensorboard"]


def _write(path, text):
    os.makedirs(os.path.dirname(path), exist_ok=True)
    with open(path, "w") as f:
        f.write(text)


def _metrics_csv(path, steps, seeds, rate, wall):
    rows = ["env_steps,seed,steps_per_second,wall_seconds,episode/target_reached"]
    rows += [f"{s},{i},{rate * seeds},{w},0.5" for s, w in zip(steps, wall) for i in range(seeds)]
    _write(path, "\n".join(rows) + "\n")


def test_listing_and_commands_on_a_hand_made_runs_folder(tmp_path):
    runs_dir = str(tmp_path / "runs")
    extra = ex.Run("c", "point-mass-ppo", dict(TOY_RUN), seeds=1, num_timesteps=10_240)
    changed = ex.Run("d", "point-mass-ppo", dict(TOY_RUN), seeds=1, num_timesteps=10_240)
    exp = ex.Experiment("toy", TOY.title, TOY.paper_ref, TOY.runs + (extra, changed))
    a, b = (os.path.join(runs_dir, "toy", n) for n in "ab")
    _write(os.path.join(a, "config.json"), json.dumps(config_json(TOY.runs[0].config(a))))
    os.makedirs(os.path.join(a, "checkpoints", "10240"))
    _write(os.path.join(a, "eval.json"), json.dumps({"env_steps": 10240, "eval_envs": 16, "per_seed": {}}))
    _write(os.path.join(b, "config.json"), json.dumps(config_json(TOY.runs[1].config(b))))
    os.makedirs(os.path.join(b, "checkpoints", "5120"))
    os.makedirs(os.path.join(b, "checkpoints", "10240.orbax-checkpoint-tmp-1"))  # an unfinished save
    _metrics_csv(os.path.join(b, "metrics.csv"), [2560, 5120], 2, 1000.0, [12.56, 2.56])
    d = os.path.join(runs_dir, "toy", "d")
    _write(os.path.join(d, "config.json"), json.dumps(config_json(ex.apply_overrides(changed.config(d), {"env.dt": 0.2}))))

    states = {r.name: ex.run_state(exp, r, runs_dir) for r in exp.runs}
    assert {n: s.status for n, s in states.items()} == {"a": "done", "b": "partial", "c": "missing", "d": "changed"}
    assert states["b"].steps == 5120 and states["b"].rate == 1000.0
    assert states["b"].startup == pytest.approx(10.0) and states["b"].wall_seconds == pytest.approx(15.12)
    assert "dt" in states["d"].reason
    text = ex.listing([(exp, list(exp.runs))], runs_dir, str(tmp_path / "out"))
    assert "1 done, 1 partial, 1 missing, 1 changed; table not built" in text
    assert "partial 0.00512M/0.01024M" in text and "total: 61,440 env steps" in text

    lines = ex.commands([(exp, list(exp.runs))], runs_dir)
    assert lines == [
        f"python train.py point-mass-ppo --logdir {b} --seeds 2 --num-timesteps 10240 --eval-envs 16 --no-tensorboard "
        f"--no-progress --seed 10 --resume",
        f"python train.py point-mass-ppo --logdir {os.path.join(runs_dir, 'toy', 'c')} --seeds 1 --num-timesteps 10240 "
        "--eval-envs 16 --no-tensorboard --no-progress"]
    assert len(ex.commands([(exp, list(exp.runs))], runs_dir, everything=True)) == 4


def test_time_limit_plan():
    st = ex.RunState("toy", TOY.runs[0], "", "partial", steps=1000, budget=100_000, rate=100.0, startup=20.0)
    assert ex.plan_stop(st, None, compiled=False) == 0  # no limit: to the end
    assert ex.plan_stop(st, 120.0, compiled=False) == 1000 + 100 * 100  # 100 s after 20 s of startup
    assert ex.plan_stop(st, 120.0, compiled=True) == 1000 + 100 * 120
    assert ex.plan_stop(st, 25.0, compiled=False) is None  # less than one log interval (2,000 steps) fits
    assert ex.plan_stop(st, 10_000.0, compiled=True) == 0  # the rest fits
    fresh = ex.RunState("toy", TOY.runs[0], "", "missing", steps=0, budget=100_000)
    assert ex.plan_stop(fresh, 5.0, compiled=False) == 4000  # no speed measured: two log intervals
    assert ex.plan_stop(fresh, 0.0, compiled=False) is None


def test_parallel_worker_commands(monkeypatch):
    monkeypatch.setenv("CUDA_VISIBLE_DEVICES", "0,1,2")
    assert ex.local_gpus() == 3
    env, argv = ex.worker_command("action-space/relative", "1", 530.7, "runs/experiments", 53.0)
    assert env["CUDA_VISIBLE_DEVICES"] == "1"
    assert argv[1:] == ["-m", "tools.experiments", "run", "action-space/relative", "--no-build", "--runs-dir",
                        "runs/experiments", "--reserve", "53", "--time-limit", "530"]


def test_toy_experiment_trains_resumes_and_builds(tmp_path):
    runs_dir, out = str(tmp_path / "runs"), str(tmp_path / "out")
    selection = ex.select(None, {"toy": TOY})
    # A deadline already passed trains nothing.
    assert not ex.train_pending(selection, runs_dir, deadline=time.monotonic() - 1, log=lambda s: None)
    assert ex.run_state(TOY, TOY.runs[0], runs_dir).status == "missing"
    # Run b is interrupted half way, as a time-limited call leaves it.
    b = TOY.runs[1]
    logdir = os.path.join(runs_dir, "toy", "b")
    assert driver.train(b.config(logdir, stop_after_steps=5120)).status == "stopped"
    assert ex.run_state(TOY, b, runs_dir).status == "partial"

    log = []
    assert ex.train_pending(selection, runs_dir, log=log.append)
    assert any("[toy/b] resuming at 5,120" in line for line in log)
    for run in TOY.runs:
        st = ex.run_state(TOY, run, runs_dir)
        assert st.status == "done" and st.steps == 10_240
    with open(os.path.join(logdir, "eval.json")) as f:
        assert json.load(f)["env_steps"] == 10_240

    files = ex.build(selection, runs_dir, out, complete_only=True, log=lambda s: None)
    assert os.path.join(out, "toy", "table.md") in files
    assert os.path.join(out, "toy", "curves.png") in files or importlib.util.find_spec("matplotlib") is None
    with open(os.path.join(out, "toy", "table.json")) as f:
        data = json.load(f)
    assert [r["run"] for r in data["rows"]] == ["a", "b"]
    assert len(data["rows"][0]["per_seed"]["target_reached"]) == 2 and data["rows"][0]["wall_seconds"] > 0
    with open(os.path.join(out, "toy", "table.md")) as f:
        text = f.read()
    assert "| paper: target reached | target reached |" in text and "| 50.0 % |" in text
    assert ex.listing(selection, runs_dir, out).splitlines()[1] == "  2 done; table built"
    assert ex.commands(selection, runs_dir) == []
