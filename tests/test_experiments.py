"""tools/experiments.py and tools/experiment_registry.py: every registered run builds a valid config (and its
train.py command parses back to it), the state listing and command list on a hand-made runs folder, the
time-limit plan, and a two-run toy experiment on the point mass that trains, resumes after an interruption and
builds its table."""

import contextlib
import dataclasses
import importlib.util
import json
import os
import re
import signal
import shutil
import subprocess
import sys
import tarfile
import time
import types

import jax
import pytest

import train
from agents import presets
from agents import driver
from agents.config import config_json
from tools import experiments as ex

TOY_RUN = dict(eval_envs=16, tensorboard=False, progress=False)
# point-mass-ppo trains 5,120 env steps per update: two updates per run. The runs differ in their seeds
# only, so they share one compiled program (the test takes a minute on a loaded 2-core CPU, not two).
TOY = ex.Experiment("toy", "point mass: two sets of seeds", "not in the paper", (
    ex.Run("a", "point-mass-ppo", dict(TOY_RUN), seeds=2, num_timesteps=10_240, paper=dict(target_reached=0.5)),
    ex.Run("b", "point-mass-ppo", {**TOY_RUN, "seed": 10}, seeds=2, num_timesteps=10_240),
), metrics=("target_reached", "distance", "wall_clock"), curves=("episode/target_reached",),
    cross=(ex.Cross("a", "wide-goal", {"goal_radius": 0.5}), ex.Cross("a", "sampled", {}, stochastic=True)))


@pytest.mark.parametrize("name", sorted(ex.EXPERIMENTS))
def test_registered_runs_are_valid_and_their_commands_parse_back(name):
    exp = ex.EXPERIMENTS[name]
    ex.validate_experiment(exp)
    for run in exp.runs:
        logdir = os.path.join(ex.RUNS_DIR, name, run.name)
        assert train.parse(run.train_args(logdir)) == run.config(logdir), run.name
        part = os.path.join(logdir, ex.part_name(2, 1))
        assert train.parse(run.train_args(part, first_seed=2, seeds=1)) == run.config(part, first_seed=2, seeds=1)


SEEDS = {"action-space": {5}, "reward": {3}, "joint-penalties": {3}, "reach-observation": {3}, "network-size": {3},
         "sac-workspaces": {3}, "reach-avoid-reward": {3, 5}, "reach-avoid-observation": {3}, "reach-avoid-front": {5},
         "obstacle-size-ur5e": {5}, "sac-reach": {5}, "sac-fast": {1, 2, 3, 5}, "obstacles-moving3": {3, 5},
         "relative-step": {3}, "reach-avoid-joint-margin": {3}, "action-latency": {3}}
"""5 seeds where the paper states numbers to compare (tables, results text) and for the rows of our own studies
(issues 25 and 29), 3 for curve-only comparisons, the static side of the moving-obstacle cross-evaluation and the
relative-step and joint-margin studies and the dense reach-avoid reward's collision-penalty test; for `sac-fast`, 5 for the rows of issue 25's protocol (the four tasks' and
the 200M Panda rows) and 1-3 for rows stopped at the seeds they have once their question was answered."""


def test_registry_covers_the_issue_with_its_seeds():
    assert {n: {r.seeds for r in e.runs} for n, e in ex.EXPERIMENTS.items()} == SEEDS
    assert all(r.budget() > 0 for e in ex.EXPERIMENTS.values() for r in e.runs)


def test_the_registry_spells_the_plus_observations_as_the_presets_do():
    from agents.presets import make_config
    from tools import experiment_registry as reg

    assert make_config("ur5e-reach-ppo-plus").env.observation == reg._PLUS_OBS
    assert make_config("ur5e-reach-avoid-ppo-plus").env.observation == reg._PLUS_AVOID_OBS
    for env in ("ur5e-reach", "panda-reach"):
        assert make_config(f"{env}-sac-fast").env.observation == reg._PLUS_OBS
    for env in ("ur5e-reach-avoid", "panda-reach-avoid"):
        assert make_config(f"{env}-sac-fast").env.observation == reg._PLUS_AVOID_OBS
    assert make_config("panda-reach-avoid-ppo-moving3").env.observation == reg._MOVING3_OBS
    assert make_config("ur5e-reach-avoid-ppo-moving3").env.observation == reg._MOVING3_PLUS_OBS


def test_every_recorded_part_still_reads_as_its_registry_run():
    """A preset edited after its runs trained must leave those rows overrides that keep their config: every part
    recorded under results/experiments (finished ones only) reads as its run's and done, not `changed` (a field a
    resume may not change) nor `partial` (a budget the override no longer pins)."""
    checked = 0
    for exp in ex.EXPERIMENTS.values():
        for run in exp.runs:
            folder = ex.record_folder(os.path.join(ex.ROOT, ex.OUT_DIR), exp.name, run.name)
            for name in sorted(os.listdir(folder)) if os.path.isdir(folder) else ():
                span = ex.parse_part(name)
                if span is not None:
                    part = ex.part_state(run, os.path.join(folder, name), *span)
                    assert part.status == "done", (exp.name, run.name, name, part.status, part.reason)
                    checked += 1
    assert checked >= 50  # the parts recorded under results/experiments


def test_table_names_a_budget_other_than_the_presets():
    preset = presets.PRESETS["panda-reach-sac-fast"].run["num_timesteps"]
    run = ex.Run("x", "panda-reach-sac-fast", {"algo.compute_dtype": "float32", "env.observation": ("joint_pos", "ee_pos")},
                 num_timesteps=100_000_000)
    assert preset == 200_000_000
    assert ex.describe_overrides(run) == "algo.compute_dtype=float32, env.observation=joint_pos+ee_pos, num_timesteps=100M"
    assert ex.describe_overrides(dataclasses.replace(run, num_timesteps=preset)) == (
        "algo.compute_dtype=float32, env.observation=joint_pos+ee_pos")  # the preset's own budget: not repeated
    assert ex.describe_overrides(ex.Run("y", "panda-reach-sac-fast")) == ""


def test_bad_overrides_and_names_raise():
    with pytest.raises(ValueError, match="env.no_such_field"):
        ex.Run("x", "point-mass-ppo", {"env.no_such_field": 1}).config()
    with pytest.raises(ValueError, match="seeds and budget are Run fields"):
        ex.Run("x", "point-mass-ppo", {"seeds": 3}).config()
    with pytest.raises(ValueError, match="goal_radius"):
        ex.validate_experiment(ex.Experiment("bad", "", "", (ex.Run("x", "point-mass-ppo", {"env.goal_radius": -1.0}),)))
    with pytest.raises(ValueError, match="registered twice"):
        ex.register(TOY, {"toy": TOY})
    with pytest.raises(ValueError, match=r"curve_groups row 'r' names runs \['a', 'zzz'\]: allowed are one or more of a, b"):
        ex.register(dataclasses.replace(TOY, curve_groups=(("r", ("a", "zzz")),)), {})
    with pytest.raises(ValueError, match=r"curve_axes=\('minutes',\) holds 'minutes': allowed are one or more of env_steps, wall_clock"):
        ex.register(dataclasses.replace(TOY, curve_axes=("minutes",)), {})
    with pytest.raises(ValueError, match=r"curve_axes=\(\) holds '\(\)'"):
        ex.register(dataclasses.replace(TOY, curve_axes=()), {})
    with pytest.raises(ValueError, match="run 'zzz' is not in experiment 'toy'"):
        ex.select(["toy/zzz"], {"toy": TOY})
    with pytest.raises(ValueError, match="experiment 'zzz' is unknown"):
        ex.select(["zzz"], {"toy": TOY})
    # Options another action would take are refused before anything is read.
    for argv, message in ((["list", "--time-limit", "60"], "--time-limit with list is meaningless: allowed is `run`"),
                          (["build", "--max-seeds", "2"], "--max-seeds with build is meaningless: allowed is `run` or "
                                                          "`commands` or `list`"),
                          (["record", "--all"], "--all with record is meaningless: allowed is `commands`"),
                          (["commands", "--no-build"], "--no-build with commands is meaningless")):
        with pytest.raises(ValueError, match=message):
            ex.main(argv)
    ex.validate_experiment(TOY)
    for cross, message in ((ex.Cross("zzz", "x", {}), "run 'zzz' is not in experiment 'toy'"),
                           (ex.Cross("a", "x", {"no_field": 1}), "env field 'no_field' is unknown for point-mass"),
                           (ex.Cross("a", "x", {"goal_radius": -1.0}), "goal_radius"),
                           (ex.Cross("a", "x/y", {}), "name='x/y' is invalid"),
                           (ex.Cross("a", "x", {}), r"env=\{\} with stochastic=False evaluates the run as trained again")):
        with pytest.raises(ValueError, match=message):
            ex.validate_experiment(dataclasses.replace(TOY, cross=(cross,)))
    # A cross that moves obstacles under a run that observed their velocity as 0 in every episode is refused at
    # registration (its policies would read the motion through a normaliser fit to one value), not after training.
    static = ex.Run("static", "panda-reach-avoid-ppo-moving3", {"env.obstacle_motion": "static"})
    blind = ex.Run("blind", "panda-reach-avoid-ppo-moving3", {
        "env.obstacle_motion": "static", "env.observation": ("joint_pos", "ee_pos", "target_pos", "obstacle_pos")})
    avoid = ex.Experiment("avoid", "static and moving", "not in the paper", (static, blind))
    with pytest.raises(ValueError, match=r"cross 'static-on-moving': env=\{'obstacle_motion': 'linear'\} changes what "
                                         r"run 'static' observed as one value in training: obstacle_vel \(trained with "
                                         r"obstacle_motion='static', here varying\)"):
        ex.validate_experiment(dataclasses.replace(avoid, cross=(ex.Cross("static", "static-on-moving",
                                                                          {"obstacle_motion": "linear"}),)))
    ex.validate_experiment(dataclasses.replace(avoid, cross=(ex.Cross("blind", "blind-on-moving",
                                                                      {"obstacle_motion": "linear"}),)))
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


def _part(run, runs_dir, exp, run_name, first, count, steps=(), evaluated=None, metrics=None, config=None,
          device=None):
    """A hand-made part folder: config.json, checkpoint folders, eval.json (with `device` where given) and
    metrics.csv as given."""
    logdir = os.path.join(runs_dir, exp, run_name, ex.part_name(first, count))
    config = config or run.config(logdir, first_seed=first, seeds=count)
    _write(os.path.join(logdir, "config.json"), json.dumps(config_json(config)))
    for step in steps:
        os.makedirs(os.path.join(logdir, "checkpoints", str(step)))
    if evaluated is not None:
        per_seed = {"episode/target_reached": [0.1 * (first + i) for i in range(count)]}
        _write(os.path.join(logdir, "eval.json"), json.dumps({"env_steps": evaluated, "eval_envs": 16, "per_seed": per_seed,
                                                              **({"device": device} if device else {})}))
    if metrics is not None:
        _metrics_csv(os.path.join(logdir, "metrics.csv"), *metrics)
    return logdir


def _fake_cross(events: list):
    """A stand-in for `ex.cross_evaluate`: notes ("cross", first seed, cross name) in `events` and writes the part's
    cross-<name>.json as the real one would."""
    def cross_evaluate(run, part, cross):
        events.append(("cross", part.first, cross.name))
        path = os.path.join(part.logdir, f"cross-{cross.name}.json")
        _write(path, json.dumps({"env_steps": 10240, "eval_envs": 16, "per_seed": {"episode/target_reached": [0.5]}}))
        return path

    return cross_evaluate


def test_read_timing_takes_the_speed_after_the_first_chunk(tmp_path):
    """The first chunk holds the compilation: the speed is the median after it, the start-up its excess; rows of
    no positive, finite speed (a hand-edited or corrupt file) are skipped; one chunk gives no speed."""
    rows = ["env_steps,seed,steps_per_second,wall_seconds", "2560,0,1000,12.56", "5120,0,0,1.0", "7680,0,nan,1.0",
            "10240,0,-5,1.0", "12800,0,1000,2.56", "15360,0,500,5.12"]
    _write(str(tmp_path / "a" / "metrics.csv"), "\n".join(rows) + "\n")
    rate, startup, wall = ex.read_timing(str(tmp_path / "a"), 1)
    assert rate == 750.0 and startup == pytest.approx(12.56 - 2560 / 750.0) and wall == pytest.approx(20.24)
    _write(str(tmp_path / "b" / "metrics.csv"), "\n".join(rows[:2]) + "\n")
    assert ex.read_timing(str(tmp_path / "b"), 1) == (None, 12.56, 12.56)
    assert ex.read_timing(str(tmp_path / "c"), 1) == (None, None, 0.0)


def test_listing_and_commands_on_a_hand_made_runs_folder(tmp_path):
    runs_dir, out = str(tmp_path / "runs"), str(tmp_path / "out")
    extra = ex.Run("c", "point-mass-ppo", {**TOY_RUN, "seed": 20}, seeds=1, num_timesteps=10_240)
    changed = ex.Run("d", "point-mass-ppo", {**TOY_RUN, "seed": 30}, seeds=1, num_timesteps=10_240)
    exp = ex.Experiment("toy", TOY.title, TOY.paper_ref, TOY.runs + (extra, changed))
    a, b = exp.runs[:2]
    _part(a, runs_dir, "toy", "a", 0, 2, steps=[10240], evaluated=10240)
    # Run b: seed 0 done on its own, seed 1 half trained (with an unfinished orbax save beside it).
    _part(b, runs_dir, "toy", "b", 0, 1, steps=[10240], evaluated=10240)
    b1 = _part(b, runs_dir, "toy", "b", 1, 1, steps=[5120], metrics=([2560, 5120], 1, 1000.0, [12.56, 2.56]))
    os.makedirs(os.path.join(b1, "checkpoints", "10240.orbax-checkpoint-tmp-1"))
    d = os.path.join(runs_dir, "toy", "d", "seeds-0-0")
    _part(changed, runs_dir, "toy", "d", 0, 1, config=ex.apply_overrides(changed.config(d), {"env.dt": 0.2}))

    states = {r.name: ex.run_state(exp, r, runs_dir) for r in exp.runs}
    assert {n: s.status for n, s in states.items()} == {"a": "done", "b": "partial", "c": "missing", "d": "changed"}
    assert states["b"].steps == 5120 and states["b"].seeds_done == 1
    part = states["b"].parts[1]
    assert (part.first, part.count, part.status, part.rate) == (1, 1, "partial", 1000.0)
    assert part.startup == pytest.approx(10.0) and part.wall_seconds == pytest.approx(15.12)
    assert "dt" in states["d"].reason and "seeds-0-0" in states["d"].reason
    text = ex.listing([(exp, list(exp.runs))], runs_dir, out)
    assert "1 done, 1 partial, 1 missing, 1 changed; table not built" in text
    assert "partial 1/2 seeds done, 0.00512M/0.01024M" in text and "total: 61,440 env steps" in text
    assert "35,840 trained" in text  # a: 2 x 10,240, b: 10,240 + 5,120, d: nothing (changed)
    # b's 15 s timed; c's config and preset have no timed part in the real registry this listing reads
    assert "; <1 GPU-min left at logged speeds + 1 part of presets never timed here" in text
    # GPU time left: b's seed 1 from its checkpoint at its own speed, a 10 s start-up + 5,120 steps at 1,000/s;
    # c (b's config but the seed) at b's speed, 10 + 10,240 / 1,000; e (another goal radius) only roughly, from
    # its preset's runs, with --max-seeds 1 as two parts of 10 + 10.24 s; f's preset never ran here.
    rough = ex.Run("e", "point-mass-ppo", {**TOY_RUN, "env.goal_radius": 0.2}, seeds=2, num_timesteps=10_240)
    untimed = ex.Run("f", "point-mass-sac", {"eval_envs": 16}, seeds=1, num_timesteps=10_240)
    registry = {"toy": dataclasses.replace(exp, runs=exp.runs + (rough, untimed))}
    assert ex.time_left(states["b"], runs_dir, registry=registry) == (pytest.approx(15.12), 0)
    assert ex.time_left(states["c"], runs_dir, registry=registry) == (pytest.approx(20.24), 0)
    st_e = ex.run_state(registry["toy"], rough, runs_dir, registry=registry)
    assert ex.guess_speed(st_e, ex.pending_parts(st_e, 1)[0], runs_dir, registry=registry) == (None, None)
    assert ex.time_left(st_e, runs_dir, registry=registry, max_seeds=1) == (pytest.approx(40.48), 0)
    # Two seeds in one part, only one-seed parts timed: b1's 1,000/s in all shared by the two, 10 + 10,240 / 500
    assert ex.time_left(st_e, runs_dir, registry=registry) == (pytest.approx(30.48), 0)
    assert ex.time_left(ex.run_state(registry["toy"], untimed, runs_dir, registry=registry), runs_dir,
                        registry=registry) == (0.0, 1)
    assert ex.time_note(0.0, 0) == "nothing left" and ex.time_note(0.0, 2) == "2 parts of presets never timed here"
    assert ex.time_note(7_200.0, 1) == "~2.0 GPU-h left at logged speeds + 1 part of presets never timed here"
    assert ex.time_note(600.0, 0) == "~10 GPU-min left at logged speeds"

    lines = ex.commands([(exp, list(exp.runs))], runs_dir)
    assert lines == [
        f"python train.py point-mass-ppo --logdir {b1} --seeds 1 --num-timesteps 10240 --eval-envs 16 --no-tensorboard "
        f"--no-progress --seed 11 --resume",
        f"python train.py point-mass-ppo --logdir {os.path.join(runs_dir, 'toy', 'c', 'seeds-0-0')} --seeds 1 "
        "--num-timesteps 10240 --eval-envs 16 --no-tensorboard --no-progress --seed 20"]
    fresh = ex.commands([(exp, list(exp.runs))], runs_dir, everything=True, max_seeds=1)
    assert len(fresh) == 6 and all("--resume" not in line for line in fresh)  # a and b as 2 x 1 seed, c, d
    # `run` records the finished parts of an experiment whose table cannot be built yet.
    recorded = ex.record([(exp, list(exp.runs))], runs_dir, out)
    assert sorted(os.path.relpath(p, out) for p in recorded) == [
        os.path.join("toy", "runs", r, part, f) for r, part in (("a", "seeds-0-1"), ("b", "seeds-0-0"))
        for f in ("config.json", "eval.json")]
    assert not ex.table_built(exp, out)


def test_a_cross_row_holds_the_parts_evaluated(tmp_path):
    """A part whose checkpoints were gone before its cross-evaluation leaves the row with the other parts' seeds."""
    runs_dir = str(tmp_path / "runs")
    b = TOY.runs[1]
    exp = dataclasses.replace(TOY, cross=(ex.Cross("b", "sampled", {}, stochastic=True),))
    _part(b, runs_dir, "toy", "b", 0, 1, steps=[10240], evaluated=10240)
    late = _part(b, runs_dir, "toy", "b", 1, 1, steps=[10240], evaluated=10240)
    _write(os.path.join(late, "cross-sampled.json"), json.dumps(
        {"env_steps": 10240, "eval_envs": 16, "per_seed": {"episode/target_reached": [0.75]}}))
    st = ex.run_state(exp, b, runs_dir)
    assert ex.cross_files(st, exp.cross[0], None) == {"seeds-1-1": os.path.join(late, "cross-sampled.json")}
    merged = ex.merged_evaluation(st, ex.cross_files(st, exp.cross[0], None))
    assert merged["seeds"] == 1 and merged["per_seed"]["episode/target_reached"] == [0.75]
    assert ex.merged_evaluation(st)["per_seed"]["episode/target_reached"] == [0.0, 0.1]  # the eval.json of both
    assert ("cross sampled: b with sampled actions: 1 of 2 parts evaluated; 1 to evaluate here (`run`), 0 without "
            "checkpoints here") in ex.listing([(exp, [b])], runs_dir, "")
    shutil.rmtree(os.path.join(runs_dir, "toy", "b", "seeds-0-0", "checkpoints"))  # a machine that did not keep them
    assert "0 to evaluate here (`run`), 1 without checkpoints here" in ex.listing([(exp, [b])], runs_dir, "")
    out = str(tmp_path / "out")
    ex.build_default(exp, [ex.run_state(exp, r, runs_dir) for r in exp.runs], os.path.join(out, "toy"), code="test")
    with open(os.path.join(out, "toy", "table.json")) as f:
        row = json.load(f)["rows"][-1]
    assert (row["status"], row["seeds_evaluated"], row["per_seed"]["target_reached"]) == ("partly evaluated", 1, [0.75])


def test_a_table_shows_the_joint_speed_and_acceleration_means_where_evaluated(tmp_path):
    """mean_joint_vel / mean_joint_acc columns: mean ± std over seeds from eval.json's episode/mean_joint_* keys,
    with their own headers and decimals; an eval.json from before the env reported them leaves the cells empty."""
    runs_dir, out = str(tmp_path / "runs"), str(tmp_path / "out")
    a, b = TOY.runs
    exp = dataclasses.replace(TOY, cross=(), metrics=("target_reached", "mean_joint_vel", "mean_joint_acc"))
    ex.validate_experiment(exp)
    with pytest.raises(ValueError,
                       match=r"metric 'joint_jerk' is unknown: allowed are .*mean_joint_vel, mean_joint_acc"):
        ex.validate_experiment(dataclasses.replace(exp, metrics=("joint_jerk",)))
    new = _part(a, runs_dir, "toy", "a", 0, 2, steps=[10240], evaluated=10240)
    _write(os.path.join(new, "eval.json"), json.dumps({"env_steps": 10240, "eval_envs": 16, "per_seed": {
        "episode/target_reached": [0.5, 0.7], "episode/mean_joint_vel": [0.5, 0.7],
        "episode/mean_joint_acc": [10.0, 14.0]}}))
    _part(b, runs_dir, "toy", "b", 0, 2, steps=[10240], evaluated=10240)  # target_reached only
    ex.build([(exp, list(exp.runs))], runs_dir, out, registry={"toy": exp}, log=lambda s: None)
    with open(os.path.join(out, "toy", "table.md")) as f:
        lines = [line for line in f.read().splitlines() if line.startswith("| ")]
    assert "| mean joint speed (rad/s) | mean joint acceleration (rad/s²) |" in lines[0]
    cells = {line.split(" | ")[0]: line.split(" | ") for line in lines}
    assert cells["| a"][4:6] == ["0.60 ± 0.10", "12.0 ± 2.0"]  # after the paper's target reached and ours
    assert cells["| b"][4:6] == ["", ""]
    with open(os.path.join(out, "toy", "table.json")) as f:
        rows = {r["run"]: r for r in json.load(f)["rows"]}
    assert rows["a"]["mean"]["mean_joint_acc"] == pytest.approx(12.0) and "mean_joint_acc" not in rows["b"]["mean"]


def test_a_partial_run_builds_a_row_of_its_done_seeds(tmp_path):
    """A run with one of two seeds done: its row and its cross row hold that seed and say how many are planned;
    a run with no seed done stays empty."""
    runs_dir, out = str(tmp_path / "runs"), str(tmp_path / "out")
    a, b = TOY.runs
    exp = dataclasses.replace(TOY, cross=(ex.Cross("b", "sampled", {}, stochastic=True),))
    done = _part(b, runs_dir, "toy", "b", 1, 1, steps=[10240], evaluated=10240, metrics=([5120, 10240], 1, 10.0, [30.0, 9.0]))
    _part(b, runs_dir, "toy", "b", 0, 1, steps=[5120])
    _write(os.path.join(done, "cross-sampled.json"), json.dumps(
        {"env_steps": 10240, "eval_envs": 16, "per_seed": {"episode/target_reached": [0.25]}}))
    assert ex.run_state(exp, b, runs_dir).status == "partial"
    assert "cross sampled: b with sampled actions: 1 of 1 parts evaluated" in ex.listing([(exp, [b])], runs_dir, "")
    written = ex.build([(exp, list(exp.runs))], runs_dir, out, registry={"toy": exp}, log=lambda s: None)
    assert os.path.join(out, "toy", "table.md") in written
    with open(os.path.join(out, "toy", "table.json")) as f:
        rows = {(r["run"], r.get("cross")): r for r in json.load(f)["rows"]}
    row, cross, empty = rows[("b", None)], rows[("b", "sampled")], rows[("a", None)]
    assert (row["status"], row["seeds_evaluated"], row["per_seed"]["target_reached"]) == ("partial", 1, [0.1])
    assert row["wall_seconds"] == pytest.approx(39.0)
    assert (cross["status"], cross["seeds_evaluated"], cross["per_seed"]["target_reached"]) == ("partly evaluated", 1, [0.25])
    assert empty["status"] == "missing" and "per_seed" not in empty
    with open(os.path.join(out, "toy", "table.md")) as f:
        table = f.read()
    assert table.count("| 1 x 16 (2 planned) |") == 2 and "| not done (missing) | 2 x - |" in table
    assert "device" not in table  # no eval.json names one: no device column
    # A device named by one part's eval.json: the row says which (and for how many of its seeds); a cross row,
    # evaluated elsewhere, has no training device.
    _part(b, runs_dir, "toy", "b", 1, 1, evaluated=10240, metrics=([5120, 10240], 1, 10.0, [30.0, 9.0]),
          device="GPU (NVIDIA H100 80GB HBM3)")
    _part(b, runs_dir, "toy", "b", 0, 1, steps=[10240], evaluated=10240, metrics=([5120, 10240], 1, 10.0, [30.0, 9.0]))
    ex.build([(exp, list(exp.runs))], runs_dir, out, registry={"toy": exp}, log=lambda s: None)
    with open(os.path.join(out, "toy", "table.md")) as f:
        lines = f.read().splitlines()
    head = next(line for line in lines if line.startswith("| run |")).split(" | ")
    by_run = {line.split(" | ")[0]: line.split(" | ") for line in lines if line.startswith("| ")}
    column = head.index("device (training's last call) |")
    assert by_run["| b"][column] == "GPU (NVIDIA H100 80GB HBM3) (1 of 2) |"
    assert by_run["| b on sampled"][column] == " |"
    assert not ex.build([(exp, list(exp.runs))], runs_dir, str(tmp_path / "other"), complete_only=True,
                        registry={"toy": exp}, log=lambda s: None)


def test_the_figure_draws_each_group_of_runs_on_its_own_row_against_both_axes(tmp_path, monkeypatch):
    """curve_groups: one row of panels per group (its runs drawn together), a panel per curve and axis; each line
    the mean over the run's seeds (hand-made logs: 0.2 and 0.6 at 5,120 steps) against env steps or against the
    running sum of the chunk times."""
    runs_dir, out = str(tmp_path / "runs"), str(tmp_path / "out")
    a, b = TOY.runs
    c = ex.Run("c", "point-mass-ppo", {**TOY_RUN, "seed": 20}, seeds=1, num_timesteps=10_240)
    exp = dataclasses.replace(TOY, runs=(a, b, c), cross=(), curves=("episode/target_reached",),
                              curve_groups=(("first", ("a", "c")), ("second", ("b",))),
                              curve_axes=("env_steps", "wall_clock"))
    ex.register(exp, {})
    for run, first in ((a, 0), (a, 1), (b, 0), (b, 1), (c, 0)):
        logdir = _part(run, runs_dir, "toy", run.name, first, 1, steps=[10240], evaluated=10240)
        value = 0.2 if first == 0 else 0.6
        _write(os.path.join(logdir, "metrics.csv"), "env_steps,seed,steps_per_second,wall_seconds,episode/target_reached\n"
               f"5120,{first},100,51.2,{value}\n10240,{first},100,51.2,{value + 0.1}\n"
               # c's part also logs a seed beyond c's one (as a part shared with a larger run): not drawn for c
               + ("5120,1,100,51.2,0.9\n10240,1,100,51.2,0.9\n" if run is c else ""))
    states = [ex.run_state(exp, r, runs_dir) for r in exp.runs]
    from tools import plots

    drawn = {}

    def spy(*args, **kwargs):
        fig = real_grid(*args, **kwargs)
        drawn.update({ax.get_title(): {l.get_label(): list(l.get_ydata()) for l in ax.get_lines()} for ax in fig.axes})
        return fig

    real_grid = plots.curve_grid
    monkeypatch.setattr(plots, "curve_grid", spy)
    path = ex.training_figure(exp, states, os.path.join(out, "curves.png"))
    monkeypatch.undo()
    assert path and os.path.isfile(path)
    assert drawn["first: " + plots.CURVE_METRICS["episode/target_reached"]]["c (1 seed)"] == pytest.approx([0.2, 0.3])

    groups = {"first": {"a": [p.logdir for p in states[0].done_parts], "c": [states[2].done_parts[0].logdir]},
              "second": {"b": [p.logdir for p in states[1].done_parts]}}
    fig = plots.curve_grid(groups, ["episode/target_reached"], ("env_steps", "wall_clock"))
    assert [ax.get_title() for ax in fig.axes] == ["first: " + plots.CURVE_METRICS["episode/target_reached"]] * 2 + [
        "second: " + plots.CURVE_METRICS["episode/target_reached"]] * 2
    assert [ax.get_xlabel() for ax in fig.axes] == [plots.X_AXES["env_steps"], plots.X_AXES["wall_clock"]] * 2
    line_a, line_c = fig.axes[0].get_lines()
    assert list(line_a.get_xdata()) == [5120, 10240] and list(line_a.get_ydata()) == pytest.approx([0.4, 0.5])
    assert line_a.get_label() == "a (2 seeds)"
    # Without `keep`, curve_grid draws every seed its logs hold: c's shared part's seed 1 too.
    assert list(line_c.get_ydata()) == pytest.approx([0.55, 0.6]) and line_c.get_label() == "c (2 seeds)"
    assert list(fig.axes[1].get_lines()[0].get_xdata()) == pytest.approx([51.2, 102.4])
    with pytest.raises(ValueError, match=r"holds 'minutes': allowed are env_steps, wall_clock"):
        plots.curve_grid(groups, ["episode/target_reached"], ("minutes",))
    from tools.experiment_spec import CURVE_AXES

    assert CURVE_AXES == tuple(plots.X_AXES)  # the registry (standard library only) spells plots' axes


def test_pending_parts_split_the_missing_seeds():
    run = ex.Run("r", "point-mass-ppo", seeds=5, num_timesteps=10_240)
    part = lambda first, count, status, steps=0: ex.PartState(f"f/{ex.part_name(first, count)}", first, count, status,
                                                              steps, 10_240)
    st = ex.RunState("e", run, "f", "partial", 0, 10_240, [part(0, 2, "done", 10_240), part(3, 1, "partial", 5_120)])
    assert [(p.first, p.count, p.steps) for p in ex.pending_parts(st)] == [(3, 1, 5_120), (2, 1, 0), (4, 1, 0)]
    st.parts = [part(1, 1, "done", 10_240)]
    assert [(p.first, p.count) for p in ex.pending_parts(st)] == [(0, 1), (2, 3)]
    assert [(p.first, p.count) for p in ex.pending_parts(st, max_seeds=2)] == [(0, 1), (2, 2), (4, 1)]
    assert ex.pending_parts(st, max_seeds=2)[1].logdir == os.path.join("f", "seeds-2-3")
    assert ex.parse_part("seeds-2-3") == (2, 2) and ex.parse_part("seeds-3-2") is None and ex.parse_part("ckpt") is None
    with pytest.raises(ValueError, match="--max-seeds=0"):
        ex.main(["list", "--max-seeds", "0"])


def test_equal_runs_train_once_and_the_record_keeps_finished_parts(tmp_path):
    runs_dir, out = str(tmp_path / "runs"), str(tmp_path / "out")
    base = ex.Run("base", "point-mass-ppo", dict(TOY_RUN), seeds=2, num_timesteps=10_240)
    same = ex.Run("same", "point-mass-ppo", dict(TOY_RUN), seeds=3, num_timesteps=10_240, label="the same config")
    other = ex.Run("other", "point-mass-ppo", {**TOY_RUN, "env.goal_radius": 0.2}, seeds=1, num_timesteps=10_240)
    first = ex.Experiment("first", "", "", (base,), metrics=("target_reached",), curves=())
    second = ex.Experiment("second", "", "", (same, other), metrics=("target_reached",), curves=())
    registry = {"first": first, "second": second}
    assert ex.storage(second, same, registry) == ("first", "base")
    assert ex.storage(second, other, registry) == ("second", "other")
    assert ex.storage(second, same, {"second": second}) == ("second", "same")  # not registered together: its own
    _part(base, runs_dir, "first", "base", 0, 2, steps=[10240], evaluated=10240)

    st = ex.run_state(second, same, runs_dir, out, registry)
    assert st.shared == "first/base" and st.folder == os.path.join(runs_dir, "first", "base")
    assert st.status == "partial" and st.seeds_done == 2
    assert [p.logdir for p in ex.pending_parts(st)] == [os.path.join(runs_dir, "first", "base", "seeds-2-2")]
    selection = ex.select(None, registry)
    text = ex.listing(selection, runs_dir, out, registry)
    assert "[trains in first/base]" in text and "total: 40,960 env steps" in text  # 3 x 10,240 once + 1 x 10,240
    lines = ex.commands(selection, runs_dir, registry=registry)
    assert len(lines) == 2 and "seeds-2-2 --seeds 1" in lines[0] and "--seed 2" in lines[0]
    # On an empty folder the run needing the most seeds plans the shared folder's parts: no seed twice.
    fresh = ex.commands(selection, str(tmp_path / "none"), max_seeds=2, registry=registry)
    assert [line.split("--logdir ")[1].split()[0].rsplit("/", 1)[1] for line in fresh] == [
        "seeds-0-1", "seeds-2-2", "seeds-0-0"]
    # A part stopped before its first checkpoint (only config.json) is started afresh.
    _part(other, runs_dir, "second", "other", 0, 1)
    assert ex.commands(ex.select(["second/other"], registry), runs_dir, registry=registry)[0].endswith("--overwrite")

    # Building only the sharing experiment records the parts in the owner's record; a checkout without the
    # runs folder sees them done.
    _part(base, runs_dir, "first", "base", 2, 1, steps=[10240], evaluated=10240)
    both = ex.record(ex.select(["first", "second"], registry), str(tmp_path / "runs"), str(tmp_path / "rec2"),
                     registry=registry)
    assert len(both) == len(set(both)) == 4  # base's seeds-0-1 and seeds-2-2, recorded once though same shares them
    files = ex.build(ex.select(["second"], registry), runs_dir, out, log=lambda s: None, registry=registry)
    record = os.path.join(out, "first", "runs", "base", "seeds-0-1")
    assert os.path.join(record, "eval.json") in files and os.path.join(record, "config.json") in files
    assert not os.path.exists(os.path.join(out, "second", "runs"))
    with open(os.path.join(out, "second", "table.json")) as f:
        row = json.load(f)["rows"][0]
    assert row["per_seed"]["target_reached"] == pytest.approx([0.0, 0.1, 0.2]) and row["shared"] == "first/base"
    assert [p["seeds"] for p in row["parts"]] == ["seeds-0-1", "seeds-2-2"]
    # The owner's own table takes its 2 seeds, not the third one trained for the sharing run.
    ex.build(ex.select(["first"], registry), runs_dir, out, log=lambda s: None, registry=registry)
    with open(os.path.join(out, "first", "table.json")) as f:
        row = json.load(f)["rows"][0]
    assert row["per_seed"]["target_reached"] == pytest.approx([0.0, 0.1]) and row["seeds_evaluated"] == 2
    elsewhere = str(tmp_path / "empty")
    assert ex.run_state(first, base, elsewhere, out, registry).status == "done"
    assert ex.run_state(first, base, elsewhere, None, registry).status == "missing"
    # Record against runs folder, same span: the done one counts; an outdated record part whose seeds are done
    # elsewhere does not block the run.
    shutil.rmtree(os.path.join(runs_dir, "first", "base", "seeds-0-1", "checkpoints"))
    os.remove(os.path.join(runs_dir, "first", "base", "seeds-0-1", "eval.json"))
    os.makedirs(os.path.join(runs_dir, "first", "base", "seeds-0-1", "checkpoints", "5120"))
    st = ex.run_state(first, base, runs_dir, out, registry)
    assert st.status == "done" and st.done_parts[0].logdir == record
    old = ex.apply_overrides(base.config(), {"env.dt": 0.2})
    _part(base, str(tmp_path / "rec"), "x", "y", 0, 2, evaluated=10240, config=old)
    os.makedirs(os.path.join(out, "first", "runs", "base", "seeds-0-0"))
    shutil.copytree(os.path.join(tmp_path, "rec", "x", "y", "seeds-0-1"), os.path.join(out, "first", "runs", "base", "seeds-0-2"))
    assert ex.run_state(first, base, runs_dir, out, registry).status == "done"  # seeds-0-2 (changed) is covered


def test_record_copies_the_finished_parts_of_a_fetched_runs_folder(tmp_path, capsys):
    """`record --runs-dir DIR`: the done parts' config.json, eval.json and metrics.csv of the selected runs into
    the results (what a GPU machine's runs/ brings back), byte for byte; a partial part stays out."""
    runs_dir, out = str(tmp_path / "fetched"), str(tmp_path / "results")
    exp = ex.EXPERIMENTS["sac-fast"]
    run = exp.run("panda-reach-plus")
    done = _part(run, runs_dir, "sac-fast", "panda-reach-plus", 0, 1, steps=[run.budget()], evaluated=run.budget(),
                 metrics=([2_000_000, run.budget()], 1, 280_000.0, [25.0, 380.0]))
    _part(run, runs_dir, "sac-fast", "panda-reach-plus", 1, 1, steps=[30_000_000])  # stopped at its time limit
    ex.main(["record", "sac-fast/panda-reach-plus", "--runs-dir", runs_dir, "--out", out])
    printed = capsys.readouterr().out
    assert printed.splitlines()[-1] == f"3 files recorded from {runs_dir} into {out}"
    folder = os.path.join(out, "sac-fast", "runs", "panda-reach-plus")
    assert sorted(os.listdir(folder)) == ["seeds-0-0"]
    for name in ("config.json", "eval.json", "metrics.csv"):
        with open(os.path.join(done, name)) as a, open(os.path.join(folder, "seeds-0-0", name)) as b:
            assert a.read() == b.read()
    assert ex.run_state(exp, run, str(tmp_path / "elsewhere"), out).seeds_done == 1
    assert not os.path.exists(os.path.join(out, "sac-fast", "table.md"))  # no table: build does that


def test_time_limit_plan():
    st = ex.PartState("", 0, 1, "partial", steps=1000, budget=100_000, rate=100.0, startup=20.0)
    assert ex.may_start(st, None, compiled=False)  # no limit
    # One log interval (2,000 steps at 100/s: 20 s) after 20 s of startup: 40 s are needed.
    assert ex.may_start(st, 40.0, compiled=False) and not ex.may_start(st, 39.9, compiled=False)
    assert ex.may_start(st, 20.0, compiled=True) and not ex.may_start(st, 19.9, compiled=True)
    near_end = dataclasses.replace(st, steps=99_500)  # 500 steps left: 5 s of training
    assert ex.may_start(near_end, 25.0, compiled=False) and not ex.may_start(near_end, 24.9, compiled=False)
    # A start-up of 60 s is paid again at the resume: at least 60 s of training (not one 20 s interval).
    slow_start = dataclasses.replace(st, startup=60.0)
    assert ex.may_start(slow_start, 120.0, compiled=False) and not ex.may_start(slow_start, 119.9, compiled=False)
    assert ex.may_start(dataclasses.replace(slow_start, steps=99_500), 65.0, compiled=False)  # it finishes in 5 s
    fresh = ex.PartState("", 0, 1, "missing", steps=0, budget=100_000)
    # No speed measured: twice the start-up (guessed from a comparable program, else ASSUMED_STARTUP) must be left.
    assert ex.ASSUMED_STARTUP == 60.0
    assert ex.may_start(fresh, 120.1, compiled=False) and not ex.may_start(fresh, 119.9, compiled=False)
    assert ex.may_start(fresh, 40.1, compiled=False, startup_guess=20.0)
    assert not ex.may_start(fresh, 39.9, compiled=False, startup_guess=20.0)
    assert not ex.may_start(fresh, 0.0, compiled=False)
    assert ex.may_start(fresh, 30.0, compiled=False, startup_guess=10.0, rate_guess=100.0)  # a sibling's speed
    assert not ex.may_start(fresh, 29.9, compiled=False, startup_guess=10.0, rate_guess=100.0)
    run = ex.Run("r", "point-mass-ppo", seeds=3, num_timesteps=100_000)
    sibling = lambda first, count, rate: ex.PartState(f"p{first}", first, count, "done", 100_000, 100_000, rate, 7.0)
    state = ex.RunState("e", run, "", "partial", 0, 100_000, [sibling(0, 2, 300.0), sibling(2, 1, 900.0)])
    assert ex.speed_guess(state, fresh) == (900.0, 7.0)  # a part of as many seeds (one) before the 2-seed one
    two = ex.PartState("y", 0, 2, "missing", 0, 100_000)
    assert ex.speed_guess(state, two) == (300.0, 7.0)
    assert ex.speed_guess(state, ex.PartState("x", 0, 3, "missing", 0, 100_000)) == (None, None)
    peer = ex.PartState("q", 0, 3, "done", 100_000, 100_000, 250.0, 9.0)  # a comparable run's 3-seed part
    assert ex.speed_guess(state, ex.PartState("x", 0, 3, "missing", 0, 100_000), [peer]) == (250.0, 9.0)
    assert ex.speed_guess(state, two, [peer]) == (300.0, 7.0)  # same count first, though the peer is slower
    lone = ex.PartState("q1", 0, 1, "done", 100_000, 100_000, 800.0, 8.0)  # a comparable run's 1-seed part
    assert ex.speed_guess(state, fresh, [peer, lone]) == (800.0, 8.0)  # the slowest of the one-seed parts
    assert ex.speed_guess(dataclasses.replace(state, parts=[sibling(0, 2, 300.0)]), fresh, [peer]) == (250.0, 9.0)
    outdated = dataclasses.replace(lone, rate=50.0, status="changed")  # trained under another config: no measure
    assert ex.speed_guess(state, fresh, [peer, lone, outdated]) == (800.0, 8.0)
    # The slowest speed with the longest start-up of the same parts, which need not be one part's pair.
    quick_start = dataclasses.replace(lone, logdir="q2", rate=850.0, startup=30.0)
    assert ex.speed_guess(state, fresh, [lone, quick_start]) == (800.0, 30.0)
    # A start-up measured as 0 s (a cached compilation) is a measurement, not a missing one.
    cached = ex.PartState("", 0, 1, "partial", steps=0, budget=100_000, rate=1000.0, startup=0.0)
    assert ex.seconds_to_finish(cached, compiled=False) == 100.0 and ex.may_start(cached, 100.0, compiled=False)


def test_a_time_limited_call_trains_one_part_until_the_clock_stops_it(tmp_path, monkeypatch):
    """A part with a measured speed is not cut at a predicted step: one driver call per part, stopped by its
    clock (`stop_after_seconds`); the next part is tried only if time is left."""
    runs_dir = str(tmp_path / "runs")
    b = TOY.runs[1]
    # Half trained at 10 env steps/s per seed after 30 s of startup: 100 s predict a stop at 5,820 of 10,240 steps.
    _part(b, runs_dir, "toy", "b", 0, 2, steps=[5120], metrics=([2560, 5120], 2, 10.0, [286.0, 256.0]))
    calls = []

    def fake_train(config, learner_cls=None):
        calls.append(config)
        return driver.TrainResult(None, 5120, "stopped", config.logdir, config, None, None)  # no progress: returns

    monkeypatch.setattr(driver, "train", fake_train)
    log = []
    assert not ex.train_pending(ex.select(["toy/b"], {"toy": TOY}), runs_dir, deadline=time.monotonic() + 130.0,
                                reserve=30.0, log=log.append)
    assert len(calls) == 1, log
    assert calls[0].resume and calls[0].stop_after_steps == 0
    assert 95.0 < calls[0].stop_after_seconds <= 100.0
    assert re.search(r"\[toy/b seeds-0-1\] resuming at 5,120; to the end of 10,240 steps x 2 seeds or (9[5-9]|100) s",
                     log[0]), log  # 100 s less what the call took so far (a loaded CPU: a second or more)


@contextlib.contextmanager
def _lock_held_elsewhere(lock: str):
    """A child process holding an exclusive flock on `lock` (writing its pid into it, as `part_lock` does) until
    the block ends, when it is killed (the kernel then drops its lock); yields its pid."""
    child = ("import fcntl, os, sys, time\n"
             "f = open(sys.argv[1], 'a+'); fcntl.flock(f, fcntl.LOCK_EX)\n"
             "f.write(f'pid {os.getpid()}'); f.flush(); print('held', flush=True)\n"
             "time.sleep(120)")
    holder = subprocess.Popen([sys.executable, "-c", child, lock], stdout=subprocess.PIPE, text=True)
    try:
        assert holder.stdout.readline().strip() == "held"
        yield holder.pid
    finally:
        holder.kill()
        holder.wait()


def test_a_part_another_process_holds_is_left_alone_until_that_process_ends(tmp_path, monkeypatch):
    """Two commands sharing a runs folder: a part whose lock another process holds (here a child process) is
    not trained and the run is left unfinished; once that process is killed the lock is free (the kernel drops a
    dead process's flock; the file it leaves holds nothing), and the part trains under this process's lock."""
    runs_dir = str(tmp_path / "runs")
    b = TOY.runs[1]
    _part(b, runs_dir, "toy", "b", 0, 2, steps=[5120], metrics=([2560, 5120], 2, 10.0, [286.0, 256.0]))
    logdir = os.path.join(runs_dir, "toy", "b", "seeds-0-1")
    lock = ex.lock_path(logdir)
    assert lock == os.path.join(runs_dir, "toy", "b", ".seeds-0-1.lock")
    calls = []

    def fake_train(config, learner_cls=None):
        with ex.part_lock(logdir) as inner:  # held by this process while it trains: a second taker is refused
            calls.append(inner)
        return driver.TrainResult(None, 5120, "stopped", config.logdir, config, None, None)

    monkeypatch.setattr(driver, "train", fake_train)
    selection = ex.select(["toy/b"], {"toy": TOY})
    with _lock_held_elsewhere(lock) as holder:
        log = []
        assert not ex.train_pending(selection, runs_dir, log=log.append)
        assert calls == [] and log == [f"[toy/b seeds-0-1] left alone: another process (pid {holder}) holds its "
                                       f"lock {lock}"], log
    assert os.path.isfile(lock)  # left behind by the killed process, holding nothing
    log = []
    assert not ex.train_pending(selection, runs_dir, log=log.append)  # stopped without progress, as above
    assert len(calls) == 1 and calls[0].startswith("another process (pid ") and f"pid {os.getpid()} on " in calls[0]
    assert "resuming at 5,120" in log[0], log
    with ex.part_lock(logdir) as free:  # released after training
        assert free is None


def test_each_part_is_cross_evaluated_and_recorded_before_the_next_trains(tmp_path, monkeypatch):
    """With `--max-seeds 1`, part 0's cross-evaluations (its run's and those of a run of another experiment
    sharing its folder) and its record happen before part 1 trains, so a call killed during part 1 keeps them."""
    runs_dir, out = str(tmp_path / "runs"), str(tmp_path / "out")
    b = TOY.runs[1]
    mine = dataclasses.replace(TOY, runs=(b,), cross=(ex.Cross("b", "sampled", {}, stochastic=True),))
    twin = ex.Experiment("twin", "the same run elsewhere", "", (ex.Run("b2", b.preset, dict(b.overrides), seeds=2,
                         num_timesteps=10_240),), cross=(ex.Cross("b2", "wide", {"goal_radius": 0.5}),))
    registry = {"toy": mine, "twin": twin}
    assert ex.storage(twin, twin.runs[0], registry) == ("toy", "b")
    events = []

    def fake_train(config, learner_cls=None):  # trains the part to its end: checkpoint, eval.json, metrics.csv
        first = config.seed - 10
        events.append(("train", first, sorted(os.listdir(os.path.join(out, "toy", "runs", "b"))) if os.path.isdir(
            os.path.join(out, "toy", "runs", "b")) else []))
        _part(b, runs_dir, "toy", "b", first, 1, steps=[10240], evaluated=10240, metrics=([5120, 10240], 1, 10.0, [30.0, 9.0]))
        return driver.TrainResult(None, 10240, "done", config.logdir, config, None, None)

    monkeypatch.setattr(driver, "train", fake_train)
    monkeypatch.setattr(ex, "cross_evaluate", _fake_cross(events))
    assert ex.train_pending(ex.select(["toy"], registry), runs_dir, log=lambda s: None, max_seeds=1, record=out,
                            registry=registry, record_each=True)
    assert [e[:2] for e in events] == [("train", 0), ("cross", 0), ("cross", 0), ("train", 1), ("cross", 1), ("cross", 1)]
    assert {e[2] for e in events if e[0] == "cross"} == {"sampled", "wide"}
    assert events[3][2] == ["seeds-0-0"]  # part 0 recorded before part 1 trained
    assert sorted(os.listdir(os.path.join(out, "toy", "runs", "b", "seeds-0-0"))) == [
        "config.json", "cross-sampled.json", "cross-wide.json", "eval.json", "metrics.csv"]
    # Nothing is left: a second call evaluates nothing more.
    events.clear()
    assert ex.train_pending(ex.select(["toy", "twin"], registry), runs_dir, log=lambda s: None, record=out,
                            registry=registry, record_each=True)
    assert events == []


def test_a_cross_evaluation_waits_for_a_call_with_time_for_it(tmp_path, monkeypatch):
    runs_dir = str(tmp_path / "runs")
    b = TOY.runs[1]
    exp = dataclasses.replace(TOY, runs=(b,), cross=(ex.Cross("b", "sampled", {}, stochastic=True),))
    _part(b, runs_dir, "toy", "b", 0, 2, steps=[10240], evaluated=10240)
    done = []
    monkeypatch.setattr(ex, "cross_evaluate", lambda run, part, cross: done.append(part.name))
    log = []
    # A first cross-evaluation needs the time one is assumed to take, and half the reserve where that is more.
    assert ex.ASSUMED_CROSS == 45.0
    assert not ex.train_pending([(exp, [b])], runs_dir, deadline=time.monotonic() + 40.0, reserve=20.0, log=log.append)
    assert done == [] and "time limit: cross-evaluation 'sampled' left for the next call" in log[-1]
    assert not ex.train_pending([(exp, [b])], runs_dir, deadline=time.monotonic() + 55.0, reserve=120.0,
                                log=log.append)
    assert done == [] and "left for the next call" in log[-1]
    assert ex.train_pending([(exp, [b])], runs_dir, deadline=time.monotonic() + 50.0, reserve=20.0, log=log.append)
    assert done == ["seeds-0-1"]


def test_a_cross_evaluation_another_process_holds_is_left_to_it(tmp_path, monkeypatch):
    """Two drivers given one row: a done part's cross-evaluation runs under the part's lock. While another process
    holds it, this one leaves the cross alone (the run unfinished); one that finds the cross written once it has
    the lock (the other finished it meanwhile) does not evaluate it again."""
    runs_dir = str(tmp_path / "runs")
    b = TOY.runs[1]
    exp = dataclasses.replace(TOY, runs=(b,), cross=(ex.Cross("b", "sampled", {}, stochastic=True),))
    _part(b, runs_dir, "toy", "b", 0, 2, steps=[10240], evaluated=10240)
    logdir = os.path.join(runs_dir, "toy", "b", "seeds-0-1")
    lock = ex.lock_path(logdir)
    done = []
    monkeypatch.setattr(ex, "cross_evaluate", lambda run, part, cross: done.append(part.name))
    with _lock_held_elsewhere(lock) as holder:
        log = []
        assert not ex.train_pending([(exp, [b])], runs_dir, log=log.append)
        assert done == [] and log == [f"[toy/b seeds-0-1] cross-evaluation 'sampled' left alone: another process "
                                      f"(pid {holder}) holds its lock {lock}"], log
    # The other process wrote the cross just before this one took the lock: nothing is evaluated twice.
    taker = ex.part_lock

    @contextlib.contextmanager
    def late_lock(path):
        with open(os.path.join(path, "cross-sampled.json"), "w") as f:
            f.write("{}")
        with taker(path) as taken:
            yield taken

    monkeypatch.setattr(ex, "part_lock", late_lock)
    log = []
    assert ex.train_pending([(exp, [b])], runs_dir, log=log.append)
    assert done == [] and log == [], log


def test_whole_parts_prediction():
    part = ex.PartState("", 0, 2, "partial", steps=20_000, budget=100_000, rate=400.0, startup=30.0)
    assert ex.seconds_to_finish(part, compiled=False) == 30.0 + 80_000 / 400.0
    assert ex.seconds_to_finish(part, compiled=True) == 200.0
    fresh = ex.PartState("", 2, 2, "missing", steps=0, budget=100_000)
    assert ex.seconds_to_finish(fresh, compiled=False) is None  # no speed: it cannot be promised
    assert ex.seconds_to_finish(fresh, compiled=False, startup_guess=45.0, rate_guess=500.0) == 245.0


def test_a_part_with_one_logged_chunk_takes_its_speed_from_a_comparable_run(tmp_path, monkeypatch):
    """A part stopped after its first chunk (compilation inside) has no speed of its own; --whole-parts then
    predicts from a run training the same config to another budget, not from that chunk."""
    runs_dir = str(tmp_path / "runs")
    short = ex.Run("short", "point-mass-ppo", dict(TOY_RUN), seeds=1, num_timesteps=10_240)
    long = ex.Run("long", "point-mass-ppo", {**TOY_RUN, "seed": 5}, seeds=1, num_timesteps=20_480)
    other = ex.Run("other", "point-mass-ppo", {**TOY_RUN, "env.dt": 0.2}, seeds=1, num_timesteps=10_240)
    exp = ex.Experiment("toy2", "point mass: budgets", "not in the paper", (short, long, other))
    registry = {"toy2": exp}
    # short: 100 env steps/s after 10 s of start-up; other (another env): 1,000/s; long: one chunk of 2,560
    # steps in 40 s, which alone would say 64 env steps/s.
    measured = _part(short, runs_dir, "toy2", "short", 0, 1, steps=[10240], evaluated=10240,
                     metrics=([5120, 10240], 1, 100.0, [61.2, 51.2]))
    _part(other, runs_dir, "toy2", "other", 0, 1, steps=[10240], evaluated=10240,
          metrics=([5120, 10240], 1, 1000.0, [15.12, 5.12]))
    _part(long, runs_dir, "toy2", "long", 0, 1, steps=[2560], metrics=([2560], 1, 64.0, [40.0]))
    part = ex.run_state(exp, long, runs_dir, registry=registry).parts[0]
    assert (part.rate, part.startup, part.wall_seconds) == (None, 40.0, 40.0)
    assert [p.logdir for p in ex.comparable_parts(long, runs_dir, registry=registry)] == [measured]
    calls, log = [], []

    def fake_train(config, learner_cls=None):
        calls.append(config.logdir)
        return driver.TrainResult(None, 2560, "stopped", config.logdir, config, None, None)  # no progress: returns

    monkeypatch.setattr(driver, "train", fake_train)
    selection = ex.select(["toy2/long"], registry)
    # 17,920 steps left at 100/s after at most 40 s of start-up, and the part's start outside the clock: 219.2 s +
    # PROCESS_START. 5 s less after the reserve (enough without PROCESS_START): left.
    need = 219.2 + ex.PROCESS_START
    assert not ex.train_pending(selection, runs_dir, deadline=time.monotonic() + 30.0 + need - 5.0, reserve=30.0,
                                log=log.append, registry=registry, whole_parts=True)
    assert calls == [] and any(f"left for a later call: it needs ~{need:.0f} s" in line for line in log), log
    assert not ex.train_pending(selection, runs_dir, deadline=time.monotonic() + 30.0 + need + 15.0, reserve=30.0,
                                log=log.append, registry=registry, whole_parts=True)
    assert calls == [os.path.join(runs_dir, "toy2", "long", "seeds-0-0")], log


def test_whole_parts_guesses_from_the_preset_where_no_comparable_run_was_timed(tmp_path, monkeypatch):
    """--whole-parts predicts a part of a config never timed from its preset's runs under other overrides
    (`guess_speed(rough=True)`) instead of leaving the GPU idle: it starts only where that prediction fits."""
    runs_dir = str(tmp_path / "runs")
    other = ex.Run("other", "point-mass-ppo", {**TOY_RUN, "env.dt": 0.2}, seeds=1, num_timesteps=10_240)
    fresh = ex.Run("fresh", "point-mass-ppo", {**TOY_RUN, "env.dt": 0.3}, seeds=1, num_timesteps=20_480)
    exp = ex.Experiment("toy3", "point mass: other overrides", "not in the paper", (other, fresh))
    registry = {"toy3": exp}
    # other: 1,000 env steps/s after 10 s of start-up; fresh: never trained, no run trains its config.
    _part(other, runs_dir, "toy3", "other", 0, 1, steps=[10240], evaluated=10240,
          metrics=([5120, 10240], 1, 1000.0, [15.12, 5.12]))
    st = ex.run_state(exp, fresh, runs_dir, registry=registry)
    part = ex.pending_parts(st)[0]
    assert ex.guess_speed(st, part, runs_dir, registry=registry) == (None, None)
    assert ex.guess_speed(st, part, runs_dir, registry=registry, rough=True) == (1000.0, 10.0)
    calls, log = [], []

    def fake_train(config, learner_cls=None):
        calls.append(config.logdir)
        return driver.TrainResult(None, 0, "stopped", config.logdir, config, None, None)

    monkeypatch.setattr(driver, "train", fake_train)
    selection = ex.select(["toy3/fresh"], registry)
    # 10 s of start-up + 20,480 steps at 1,000/s + PROCESS_START; 5 s less after the reserve: left, the guess named.
    need = 30.48 + ex.PROCESS_START
    assert not ex.train_pending(selection, runs_dir, deadline=time.monotonic() + 30.0 + need - 5.0, reserve=30.0,
                                log=log.append, registry=registry, whole_parts=True)
    assert calls == [] and any(f"it needs ~{need:.0f} s (a rough guess from other runs of its preset)" in line
                               for line in log), log
    # 10 s more than it needs after the reserve: started, though the time limit's own rule (which takes no rough
    # guess) would ask for more than twice the assumed start-up.
    assert need + 10.0 < 2 * ex.ASSUMED_STARTUP
    ex.train_pending(selection, runs_dir, deadline=time.monotonic() + 30.0 + need + 10.0, reserve=30.0,
                     log=log.append, registry=registry, whole_parts=True)
    assert calls == [os.path.join(runs_dir, "toy3", "fresh", "seeds-0-0")], log


def test_rough_guess_from_parts_of_fewer_seeds_shares_their_throughput(tmp_path):
    """With no part of as many seeds measured, a rough guess shares the slowest throughput in all of the
    preset's parts of fewer seeds among the part's seeds, and plans on the longest start-up among them."""
    runs_dir = str(tmp_path / "runs")
    quick = ex.Run("quick", "point-mass-ppo", {**TOY_RUN, "env.dt": 0.2}, seeds=1, num_timesteps=10_240)
    slow = ex.Run("slow", "point-mass-ppo", {**TOY_RUN, "env.dt": 0.25}, seeds=1, num_timesteps=10_240)
    pair = ex.Run("pair", "point-mass-ppo", {**TOY_RUN, "env.dt": 0.3}, seeds=2, num_timesteps=20_480)
    exp = ex.Experiment("toy4", "point mass: seeds", "not in the paper", (quick, slow, pair))
    registry = {"toy4": exp}
    # quick: 1,000 env steps/s after 40 s of start-up; slow: 800/s after 10 s (5,120 / 800 = 6.4 s).
    _part(quick, runs_dir, "toy4", "quick", 0, 1, steps=[10240], evaluated=10240,
          metrics=([5120, 10240], 1, 1000.0, [45.12, 5.12]))
    _part(slow, runs_dir, "toy4", "slow", 0, 1, steps=[10240], evaluated=10240,
          metrics=([5120, 10240], 1, 800.0, [16.4, 6.4]))
    st = ex.run_state(exp, pair, runs_dir, registry=registry)
    part = ex.pending_parts(st)[0]
    assert part.count == 2
    rate, startup = ex.guess_speed(st, part, runs_dir, registry=registry, rough=True)
    assert rate == pytest.approx(400.0) and startup == pytest.approx(40.0)


def test_rough_guess_prefers_runs_of_the_same_learner_config(tmp_path):
    """A rough guess takes the preset's runs with the part's learner config (other env overrides) before those of
    another network, which train slower: the planner then leaves no GPU idle for a part that would fit."""
    runs_dir = str(tmp_path / "runs")
    env_only = ex.Run("env-only", "point-mass-ppo", {**TOY_RUN, "env.dt": 0.2}, seeds=1, num_timesteps=10_240)
    wider = ex.Run("wider", "point-mass-ppo", {**TOY_RUN, "algo.policy_hidden_sizes": (64, 64, 64)}, seeds=1,
                   num_timesteps=10_240)
    fresh = ex.Run("fresh", "point-mass-ppo", {**TOY_RUN, "env.dt": 0.3}, seeds=1, num_timesteps=10_240)
    registry = {"toy5": ex.Experiment("toy5", "point mass: learners", "not in the paper", (env_only, wider, fresh))}
    assert ex.learner_key(env_only) == ex.learner_key(fresh) != ex.learner_key(wider)
    # On an arm, the observation leaves the key alone; the physics' substeps and the backend change it.
    arm = [ex.learner_key(ex.Run("arm", "ur5e-reach-ppo", overrides)) for overrides in (
        {}, {"env.observation": ("joint_pos", "ee_pos", "target_pos")}, {"env.substeps": 3}, {"env.backend": "mujoco"})]
    assert arm[0] == arm[1] and len({arm[0], arm[2], arm[3]}) == 3
    # env-only: 1,000 env steps/s after 10 s of start-up; wider: 500/s after 30 s.
    _part(env_only, runs_dir, "toy5", "env-only", 0, 1, steps=[10240], evaluated=10240,
          metrics=([5120, 10240], 1, 1000.0, [15.12, 5.12]))
    _part(wider, runs_dir, "toy5", "wider", 0, 1, steps=[10240], evaluated=10240,
          metrics=([5120, 10240], 1, 500.0, [40.24, 10.24]))
    st = ex.run_state(registry["toy5"], fresh, runs_dir, registry=registry)
    part = ex.pending_parts(st)[0]
    assert ex.guess_speed(st, part, runs_dir, registry=registry) == (None, None)
    rate, startup = ex.guess_speed(st, part, runs_dir, registry=registry, rough=True)
    assert rate == pytest.approx(1000.0) and startup == pytest.approx(10.0)
    # Without a run of its learner config, the whole preset's slowest: wider's.
    lone = ex.Run("lone", "point-mass-ppo", {**TOY_RUN, "algo.value_hidden_sizes": (8,)}, seeds=1,
                  num_timesteps=10_240)
    registry["toy5"] = dataclasses.replace(registry["toy5"], runs=registry["toy5"].runs + (lone,))
    st = ex.run_state(registry["toy5"], lone, runs_dir, registry=registry)
    rate, startup = ex.guess_speed(st, ex.pending_parts(st)[0], runs_dir, registry=registry, rough=True)
    assert rate == pytest.approx(500.0) and startup == pytest.approx(30.0)


def test_whole_parts_leaves_a_part_that_cannot_finish(tmp_path):
    runs_dir = str(tmp_path / "runs")
    b = TOY.runs[1]
    logdir = os.path.join(runs_dir, "toy", "b", "seeds-0-1")
    assert driver.train(b.config(logdir, stop_after_steps=5120)).status == "stopped"
    before = ex.checkpoint_steps(logdir)
    selection = ex.select(["toy/b"], {"toy": TOY})
    log = []
    # 1 s left after the reserve cannot finish the remaining 5,120 steps with a compilation first (nor can a speed
    # be promised: its one logged chunk holds the compilation).
    assert not ex.train_pending(selection, runs_dir, deadline=time.monotonic() + 31.0, reserve=30.0, log=log.append,
                                whole_parts=True)
    assert any("[toy/b seeds-0-1] left for a later call: it needs an unknown time" in line for line in log), log
    assert ex.checkpoint_steps(logdir) == before == [5120]
    # With time to spare and the speed of a run that trains a's and b's config (seeds apart) to another budget (c,
    # made by hand: 2,048 env steps/s per seed), a (never started) and b are predicted to finish, and do.
    c = ex.Run("c", "point-mass-ppo", {**TOY_RUN, "seed": 30}, seeds=2, num_timesteps=20_480)
    registry = {"toy": dataclasses.replace(TOY, runs=TOY.runs + (c,))}
    _part(c, runs_dir, "toy", "c", 0, 2, steps=[20480], evaluated=20480, metrics=([10240, 20480], 2, 2048.0, [15.0, 5.0]))
    log.clear()
    both = ex.select(["toy/a", "toy/b"], registry)
    assert ex.train_pending(both, runs_dir, deadline=time.monotonic() + 600.0, reserve=30.0, log=log.append,
                            whole_parts=True, registry=registry), log
    assert not any("left for a later call" in line for line in log), log
    assert ex.run_state(TOY, TOY.runs[0], runs_dir).status == ex.run_state(TOY, b, runs_dir).status == "done"
    with pytest.raises(ValueError, match=r"--whole-parts without --time-limit"):
        ex.main(["run", "toy", "--whole-parts"])


@pytest.fixture
def jax_platforms_unset():
    """jax_platforms cleared for the test (so that a test can see who sets it) and restored after it."""
    before = jax.config.jax_platforms
    jax.config.update("jax_platforms", None)
    yield
    jax.config.update("jax_platforms", before)


def test_parallel_worker_commands(monkeypatch, jax_platforms_unset):
    monkeypatch.setenv("CUDA_VISIBLE_DEVICES", "0,1,2")
    assert ex.local_gpus() == ["0", "1", "2"]
    monkeypatch.setenv("CUDA_VISIBLE_DEVICES", "2, 3,2")  # a second driver on the same host: its workers get 2 and 3
    assert ex.local_gpus() == ["2", "3"]
    with pytest.raises(ValueError, match=r"--gpus=0 is impossible"):
        ex.main(["run", "sac-fast", "--parallel", "--gpus", "0"])
    given = []
    monkeypatch.setattr(ex, "train_parallel", lambda selection, runs_dir, gpus, *args, **kw: given.append(gpus) or True)
    ex.main(["run", "sac-fast", "--parallel", "--gpus", "1", "--no-build"])
    ex.main(["run", "sac-fast", "--parallel", "--no-build"])
    assert given == [["2"], ["2", "3"]]  # --gpus N takes the first N of the visible GPUs
    assert jax.config.jax_platforms == "cpu"  # the driver's own jax stays off the workers' GPUs
    env, argv = ex.worker_command("action-space/relative", "1", 530.7, "runs/experiments", 53.0, max_seeds=1)
    assert env["CUDA_VISIBLE_DEVICES"] == "1"
    assert argv[1:] == ["-m", "tools.experiments", "run", "action-space/relative", "--no-build", "--runs-dir",
                        "runs/experiments", "--out", "results/experiments", "--reserve", "53", "--time-limit", "530",
                        "--max-seeds", "1"]
    _, argv = ex.worker_command("action-space/relative", "0", None, "runs/experiments", 30.0, whole_parts=True)
    assert argv[-1] == "--whole-parts" and "--time-limit" not in argv
    _, argv = ex.worker_command("action-space/relative", "2", None, "runs/experiments", 30.0, only_part="seeds-3-3")
    assert argv[-2:] == ["--only-part", "seeds-3-3"]
    nowhere = ["--time-limit", "0", "--no-build", "--runs-dir", "/nonexistent/runs", "--out", "/nonexistent/out"]
    with pytest.raises(ValueError, match=rf"--only-part='seeds-0-0' needs `run` of exactly one run .*given run of {len(ex.EXPERIMENTS['sac-fast'].runs)} runs"):
        ex.main(["run", "sac-fast", "--only-part", "seeds-0-0", *nowhere])
    for name in ("seed-1", "seeds-3-1", "seeds-01-2"):
        with pytest.raises(ValueError, match=rf"--only-part='{name}' is not a part name: allowed is seeds-<first>-<last>"):
            ex.main(["run", "sac-fast/panda-reach", "--only-part", name, *nowhere])


def test_run_carries_unfinished_parts_in_and_out_within_its_time_limit(monkeypatch, tmp_path, jax_platforms_unset):
    """`run --carry-in A --carry-out B`: the parts packed in A are put into the runs folder before any training,
    the unfinished ones packed into B after it, and a time limit keeps CARRY_RESERVE's seconds for the packing
    (30 s + 15 s per worker slot: 60 s on two GPUs)."""
    from tools import carry_parts

    events = []
    monkeypatch.setattr(carry_parts, "unpack", lambda source, runs_dir: events.append(("unpack", source, runs_dir)))
    monkeypatch.setattr(carry_parts, "pack", lambda runs_dir, to, **kw: events.append(("pack", runs_dir, to, kw)))
    monkeypatch.setattr(ex, "train_parallel", lambda selection, runs_dir, gpus, deadline, *a, **kw:
                        events.append(("train", gpus, deadline - time.monotonic())) or True)
    monkeypatch.setattr(ex, "train_pending", lambda selection, runs_dir, deadline, *a, **kw:
                        events.append(("train", None, deadline)) or True)
    monkeypatch.setenv("CUDA_VISIBLE_DEVICES", "0,1")
    carry_in, carry_out, runs_dir = str(tmp_path / "in"), str(tmp_path / "out"), str(tmp_path / "runs")
    os.makedirs(carry_in)
    with open(os.path.join(carry_in, "toy__a__seeds-0-0.tgz.000"), "wb") as f:
        f.write(b"")
    common = ["--runs-dir", runs_dir, "--no-build", "--carry-in", carry_in, "--carry-out", carry_out]
    ex.main(["run", "sac-fast", "--parallel", "--time-limit", "500", *common])
    assert [e[0] for e in events] == ["unpack", "train", "pack"]
    everything = ex.run_folders(ex.select(["sac-fast"]))
    assert "sac-fast/panda-reach-plus-200m" in everything and "action-space/relative" in everything  # its PPO row's
    assert events[0][1:] == (carry_in, runs_dir) and events[2][1:] == (
        runs_dir, carry_out, {"max_total_mb": carry_parts.TOTAL_MB, "runs": everything})
    assert events[1][1] == ["0", "1"] and 438.0 < events[1][2] <= 440.0  # 500 s less 30 + 2 x 15
    events.clear()
    os.remove(os.path.join(carry_in, "toy__a__seeds-0-0.tgz.000"))  # nothing to unpack; no limit, no reserve
    # Only the named runs' parts are packed (another command may train other runs in the same folder), in the
    # folder that trains them (sac-fast's UR5e reach PPO row shares action-space/relative).
    ex.main(["run", "sac-fast/panda-reach-plus-200m", "sac-fast/ur5e-reach-ppo", *common, "--carry-max-mb", "40"])
    assert events == [("train", None, None), ("pack", runs_dir, carry_out, {
        "max_total_mb": 40.0, "runs": ["action-space/relative", "sac-fast/panda-reach-plus-200m"]})]
    with pytest.raises(ValueError, match=r"--carry-max-mb=0.0 is invalid"):
        ex.main(["run", "sac-fast", *common, "--carry-max-mb", "0"])
    with pytest.raises(ValueError, match=r"--carry-max-mb without --carry-out is meaningless"):
        ex.main(["run", "sac-fast", "--no-build", "--carry-max-mb", "40"])
    with pytest.raises(ValueError, match=r"--carry-in='.*nowhere' is not a folder"):
        ex.main(["run", "sac-fast", "--carry-in", str(tmp_path / "nowhere"), "--no-build"])
    with pytest.raises(ValueError, match=r"--carry-out with list is meaningless"):
        ex.main(["list", "--carry-out", carry_out])


def test_run_shares_a_persistent_compilation_cache_with_its_workers(monkeypatch, tmp_path, jax_platforms_unset):
    """`run` turns on JAX's compilation cache for itself and passes the same setting to the workers it starts
    (`--compilation-cache`): by default in .jax_cache/ of the repository, else the folder given or named by
    JAX_COMPILATION_CACHE_DIR; `off` reaches the workers too."""
    before = jax.config.jax_compilation_cache_dir
    monkeypatch.delenv("JAX_COMPILATION_CACHE_DIR", raising=False)
    given = []
    monkeypatch.setattr(ex, "train_parallel", lambda *args, **kw: given.append(kw["compilation_cache"]) or True)
    monkeypatch.setattr(ex, "train_pending", lambda *args, **kw: True)
    monkeypatch.setenv("CUDA_VISIBLE_DEVICES", "0")
    default = os.path.join(ex.ROOT, ".jax_cache")
    try:
        ex.main(["run", "sac-fast", "--no-build"])
        assert jax.config.jax_compilation_cache_dir == default
        mine = str(tmp_path / "cache")
        monkeypatch.setenv("JAX_COMPILATION_CACHE_DIR", mine)  # a user's own cache is kept
        ex.main(["run", "sac-fast", "--parallel", "--no-build"])
        assert jax.config.jax_compilation_cache_dir == mine and given == [mine]
        ex.main(["run", "sac-fast", "--parallel", "--no-build", "--compilation-cache", "off"])
        assert jax.config.jax_compilation_cache_dir is None and given == [mine, None]
        _, argv = ex.worker_command("a/b", "0", None, "r", 30.0, compilation_cache=mine)
        assert argv[-2:] == ["--compilation-cache", mine]
        assert "--compilation-cache" not in ex.worker_command("a/b", "0", None, "r", 30.0)[1]  # the worker's default
        with pytest.raises(ValueError, match=r"--compilation-cache with list is meaningless"):
            ex.main(["list", "--compilation-cache", mine])
    finally:
        jax.config.update("jax_compilation_cache_dir", before)


def test_workers_past_the_time_limit_are_interrupted_then_killed(tmp_path, monkeypatch):
    """A worker still running WORKER_GRACE[0] s past the driver's deadline gets SIGINT (it checkpoints and exits),
    one still running WORKER_GRACE[1] s past it is killed, so the call returns about a minute late at most.
    Here two workers ignore SIGINT (as one stuck in a compilation would); a hand-made clock advances by the
    driver's 2 s sleeps."""
    runs_dir = str(tmp_path / "runs")
    selection = ex.select(["toy/b"], {"toy": TOY})
    now = [0.0]

    def sleep(seconds):
        now[0] += seconds
        assert now[0] < 1000.0, "the driver still waits for its workers long after the time limit"

    monkeypatch.setattr(ex, "time", types.SimpleNamespace(monotonic=lambda: now[0], sleep=sleep))
    workers = []

    class Stubborn:
        def __init__(self, argv, env, cwd, stdout=None, stderr=None):
            self.returncode, self.signals, self.argv = None, [], argv
            workers.append(self)

        def poll(self):
            return self.returncode

        def send_signal(self, sig):
            self.signals.append((now[0], sig))

        def kill(self):
            self.signals.append((now[0], "kill"))
            self.returncode = -9

    monkeypatch.setattr(ex.subprocess, "Popen", Stubborn)
    lines = []
    deadline = 300.0  # 270 s after the 30 s reserve: both seeds of toy/b start (no speed known: 120 s needed)
    assert not ex.train_parallel(selection, runs_dir, ["0", "1"], deadline, 30.0, log=lines.append, max_seeds=1)
    assert len(workers) == 2
    assert all(w.argv[-2:] == ["--compilation-cache", "off"] for w in workers)  # the driver's setting: none
    for w in workers:
        (t_int, sig), (t_kill, kill) = w.signals
        assert sig == signal.SIGINT and kill == "kill"
        assert deadline + ex.WORKER_GRACE[0] < t_int <= deadline + ex.WORKER_GRACE[0] + 2
        assert deadline + ex.WORKER_GRACE[1] < t_kill <= deadline + ex.WORKER_GRACE[1] + 2
    assert now[0] <= deadline + ex.WORKER_GRACE[1] + 6  # the kill, then two of the driver's 2 s sleeps
    assert sum("past the time limit: interrupted (SIGINT)" in line for line in lines) == 2
    assert sum("exited with status -9" in line for line in lines) == 2


def test_round_robin_takes_a_seed_of_each_run_first_after_the_parts_with_checkpoints(tmp_path):
    """`run --parallel --round-robin --max-seeds 1`: the part with a checkpoint (here c's seed 2) first, then the
    first new seed of b and d, then their second and c's first new one (a run's new parts rank after the seeds it
    has done or started), and so on; without it, run after run (each run's part with a checkpoint before its new ones)."""
    runs_dir, out = str(tmp_path / "runs"), str(tmp_path / "out")
    runs = tuple(ex.Run(name, "point-mass-ppo", {**TOY_RUN, "seed": 10 * i}, seeds=3 if name == "c" else 2,
                        num_timesteps=10_240) for i, name in enumerate("bcd", 1))
    registry = {"toy": dataclasses.replace(TOY, runs=runs, cross=())}
    _part(runs[1], runs_dir, "toy", "c", 2, 1, steps=[5120])  # half trained
    selection = ex.select(["toy"], registry)
    robin = ex.parallel_items(selection, runs_dir, max_seeds=1, out=out, registry=registry, round_robin=True)
    assert robin == [("toy/c", "seeds-2-2"), ("toy/b", "seeds-0-0"), ("toy/d", "seeds-0-0"), ("toy/b", "seeds-1-1"),
                     ("toy/c", "seeds-0-0"), ("toy/d", "seeds-1-1"), ("toy/c", "seeds-1-1")]
    in_order = ex.parallel_items(selection, runs_dir, max_seeds=1, out=out, registry=registry)
    assert in_order == [("toy/b", "seeds-0-0"), ("toy/b", "seeds-1-1"), ("toy/c", "seeds-2-2"), ("toy/c", "seeds-0-0"),
                        ("toy/c", "seeds-1-1"), ("toy/d", "seeds-0-0"), ("toy/d", "seeds-1-1")]
    # c's first seed half trained and b's done: d's first seed comes before a second seed of b or c
    runs_dir2 = str(tmp_path / "runs2")
    _part(runs[1], runs_dir2, "toy", "c", 0, 1, steps=[5120])
    _part(runs[0], runs_dir2, "toy", "b", 0, 1, steps=[10240], evaluated=10240)
    robin = ex.parallel_items(selection, runs_dir2, max_seeds=1, out=out, registry=registry, round_robin=True)
    assert robin == [("toy/c", "seeds-0-0"), ("toy/d", "seeds-0-0"), ("toy/b", "seeds-1-1"), ("toy/c", "seeds-1-1"),
                     ("toy/d", "seeds-1-1"), ("toy/c", "seeds-2-2")]
    with pytest.raises(ValueError, match="--round-robin without --parallel"):
        ex.main(["run", "toy", "--round-robin"])


def test_round_robin_ranks_new_parts_by_the_seeds_their_run_has_before_them(tmp_path):
    """Parts of two seeds (`--max-seeds 2`): b has two done one-seed parts, c one done two-seed part, d nothing.
    Both b and c hold two seeds, so their new parts rank together, after d's first and beside d's second
    (counting parts instead would put c's before b's and d's second before b's)."""
    runs_dir, out = str(tmp_path / "runs"), str(tmp_path / "out")
    runs = tuple(ex.Run(name, "point-mass-ppo", {**TOY_RUN, "seed": 10 * i}, seeds=4, num_timesteps=10_240)
                 for i, name in enumerate("bcd", 1))
    registry = {"toy": dataclasses.replace(TOY, runs=runs, cross=())}
    for first in (0, 1):
        _part(runs[0], runs_dir, "toy", "b", first, 1, steps=[10240], evaluated=10240)
    _part(runs[1], runs_dir, "toy", "c", 0, 2, steps=[10240], evaluated=10240)
    selection = ex.select(["toy"], registry)
    robin = ex.parallel_items(selection, runs_dir, max_seeds=2, out=out, registry=registry, round_robin=True)
    assert robin == [("toy/d", "seeds-0-1"), ("toy/b", "seeds-2-3"), ("toy/c", "seeds-2-3"), ("toy/d", "seeds-2-3")]


def test_parallel_spreads_the_parts_of_one_run_over_the_gpus(tmp_path, monkeypatch):
    """`run --parallel --max-seeds 1`: each seed of a run is its own worker (`--only-part`), the done parts'
    cross-evaluations left behind are workers too (first, while their checkpoints are here), and a worker
    trains and evaluates its part alone."""
    runs_dir, out = str(tmp_path / "runs"), str(tmp_path / "out")
    b = TOY.runs[1]
    c = ex.Run("c", "point-mass-ppo", {**TOY_RUN, "seed": 20}, seeds=2, num_timesteps=10_240)
    exp = dataclasses.replace(TOY, runs=(b, c), cross=(ex.Cross("b", "sampled", {}, stochastic=True),
                                                        ex.Cross("c", "sampled-c", {}, stochastic=True)))
    registry = {"toy": exp}
    for run in (b, c):  # seed 0 of each done, its cross-evaluation not run
        _part(run, runs_dir, "toy", run.name, 0, 1, steps=[10240], evaluated=10240)
    selection = ex.select(["toy"], registry)
    items = ex.parallel_items(selection, runs_dir, max_seeds=1, out=out, registry=registry)
    assert items == [("toy/b", "seeds-0-0"), ("toy/c", "seeds-0-0"), ("toy/b", "seeds-1-1"), ("toy/c", "seeds-1-1")]
    # The driver: two GPUs, three workers, each started with its part (fake processes that end at once).
    started = []

    class FakeProcess:
        def __init__(self, argv, env, cwd, stdout=None, stderr=None):
            started.append((env["CUDA_VISIBLE_DEVICES"], argv[argv.index("run") + 1], argv[argv.index("--only-part") + 1]))
            stdout.write(f"worker of {argv[argv.index('--only-part') + 1]}\n")
            self.returncode = 0

        def poll(self):
            return 0

    monkeypatch.setattr(ex.subprocess, "Popen", FakeProcess)
    monkeypatch.setattr(ex, "parallel_items", lambda *args, **kw: list(items))
    original_worker_command = ex.worker_command
    monkeypatch.setattr(ex.time, "sleep", lambda s: None)
    logs = str(tmp_path / "logs")
    assert not ex.train_parallel(selection, runs_dir, ["0", "1"], None, 30.0, log=lambda s: None, max_seeds=1, out=out,
                                 worker_logs=logs)
    assert started == [("0", "toy/b", "seeds-0-0"), ("1", "toy/c", "seeds-0-0"), ("0", "toy/b", "seeds-1-1"),
                       ("1", "toy/c", "seeds-1-1")]
    assert sorted(os.listdir(logs)) == ["toy_b_seeds-0-0.log", "toy_b_seeds-1-1.log", "toy_c_seeds-0-0.log",
                                        "toy_c_seeds-1-1.log"]
    with open(os.path.join(logs, "toy_b_seeds-1-1.log")) as f:
        assert f.read() == "worker of seeds-1-1\n"
    # 100 s to the deadline, 30 of them the reserve: the parts to train (no speed measured) would need twice the
    # assumed 60 s start-up, so the driver starts no worker for them (one would stop at once, after its process
    # start); the cross-evaluations of the done parts still get theirs.
    started.clear()
    lines = []
    assert not ex.train_parallel(selection, runs_dir, ["0", "1"], time.monotonic() + 100.0, 30.0, log=lines.append,
                                 max_seeds=1, out=out, worker_logs=logs)
    assert started == [("0", "toy/b", "seeds-0-0"), ("1", "toy/c", "seeds-0-0")]
    assert sum("not started: time limit: stopped at 0 of 10,240 steps" in line for line in lines) == 2, lines
    started.clear()  # with 200 s they start
    assert not ex.train_parallel(selection, runs_dir, ["0", "1"], time.monotonic() + 200.0, 30.0, log=lambda s: None,
                                 max_seeds=1, out=out, worker_logs=logs)
    assert len(started) == 4
    with pytest.raises(ValueError, match=r"--worker-logs without --parallel is meaningless"):
        ex.main(["run", "sac-fast", "--worker-logs", logs])
    # Two workers on one GPU, each with 45 % of its memory.
    started.clear()
    fractions = []
    monkeypatch.setattr(ex, "worker_command", lambda *args: fractions.append(
        original_worker_command(*args)[0].get("XLA_PYTHON_CLIENT_MEM_FRACTION")) or original_worker_command(*args))
    lines = []
    assert not ex.train_parallel(selection, runs_dir, ["3"], None, 30.0, log=lines.append, max_seeds=1, out=out,
                                 worker_logs=logs, workers_per_gpu=2)
    assert [gpu for gpu, _, _ in started] == ["3"] * 4 and fractions == ["0.450"] * 4
    assert [line.split(" (output")[0] for line in lines[:3]] == [  # both started before either ended
        "GPU 3 worker 0: toy/b seeds-0-0", "GPU 3 worker 1: toy/c seeds-0-0", "GPU 3 worker 0: toy/b seeds-0-0 exited with status 0"]
    with pytest.raises(ValueError, match=r"--workers-per-gpu without --parallel is meaningless"):
        ex.main(["run", "sac-fast", "--workers-per-gpu", "2"])
    with pytest.raises(ValueError, match=r"--workers-per-gpu=0 is impossible"):
        ex.main(["run", "sac-fast", "--parallel", "--workers-per-gpu", "0"])
    monkeypatch.undo()
    # A worker: its own part alone (trained, then cross-evaluated), never the other parts of its run.
    events = []

    def fake_train(config, learner_cls=None):
        first = config.seed - 10
        events.append(("train", first))
        _part(b, runs_dir, "toy", "b", first, 1, steps=[10240], evaluated=10240, metrics=([5120, 10240], 1, 10.0, [30.0, 9.0]))
        return driver.TrainResult(None, 10240, "done", config.logdir, config, None, None)

    monkeypatch.setattr(driver, "train", fake_train)
    monkeypatch.setattr(ex, "cross_evaluate", _fake_cross(events))
    worker = ex.select(["toy/b"], registry)
    log = []
    assert not ex.train_pending(worker, runs_dir, max_seeds=1, record=out, registry=registry, log=log.append,
                                only_part="seeds-4-4")
    assert events == [] and "[toy/b] no part seeds-4-4 to train: its parts are seeds-1-1 (with --max-seeds 1)" in log
    # True: its part is done and evaluated, while the run is not.
    assert ex.train_pending(worker, runs_dir, max_seeds=1, record=out, registry=registry, log=log.append,
                            only_part="seeds-0-0")
    assert events == [("cross", 0, "sampled")] and ex.run_state(exp, b, runs_dir, out, registry).status == "partial"
    events.clear()
    assert ex.train_pending(worker, runs_dir, max_seeds=1, record=out, registry=registry, log=log.append,
                            only_part="seeds-1-1")
    assert events == [("train", 1), ("cross", 1, "sampled")] and ex.run_state(exp, b, runs_dir, out, registry).status == "done"


def test_toy_experiment_trains_resumes_and_builds(tmp_path):
    runs_dir, out = str(tmp_path / "runs"), str(tmp_path / "out")
    selection = ex.select(None, {"toy": TOY})
    # A deadline already passed trains nothing.
    assert not ex.train_pending(selection, runs_dir, deadline=time.monotonic() - 1, log=lambda s: None)
    assert ex.run_state(TOY, TOY.runs[0], runs_dir).status == "missing"
    # Run b is interrupted half way, as a time-limited call leaves it.
    b = TOY.runs[1]
    logdir = os.path.join(runs_dir, "toy", "b", "seeds-0-1")
    assert driver.train(b.config(logdir, stop_after_steps=5120)).status == "stopped"
    assert ex.run_state(TOY, b, runs_dir).status == "partial"
    # Run a was killed before its first checkpoint: config.json alone; the runner starts it afresh.
    a_logdir = os.path.join(runs_dir, "toy", "a", "seeds-0-1")
    _write(os.path.join(a_logdir, "config.json"), json.dumps(config_json(TOY.runs[0].config(a_logdir))))

    log = []
    assert ex.train_pending(selection, runs_dir, log=log.append)
    assert any("[toy/b seeds-0-1] resuming at 5,120" in line for line in log)
    for run in TOY.runs:
        st = ex.run_state(TOY, run, runs_dir)
        assert st.status == "done" and st.steps == 10_240
    with open(os.path.join(logdir, "eval.json")) as f:
        written = json.load(f)
    from agents.evaluation import device_description

    assert written["env_steps"] == 10_240 and written["device"] == device_description() == f"CPU, {os.cpu_count()} cores"

    # The cross-evaluation ran once run a was done: its policies on a 0.5 m goal, as eval.py computes it.
    a_part = ex.run_state(TOY, TOY.runs[0], runs_dir).done_parts[0]
    with open(os.path.join(a_part.logdir, "cross-wide-goal.json")) as f:
        cross = json.load(f)
    from agents import evaluation

    env = dataclasses.replace(TOY.runs[0].config().env, goal_radius=0.5)
    direct = evaluation.run(evaluation.checkpoint_policy(a_part.logdir), "point-mass", env, num_envs=16,
                            eval_seeds=(1_000_000,))
    assert cross["per_seed"]["episode/target_reached"] == pytest.approx([u["metrics"]["target_reached"] for u in direct.units])
    with open(os.path.join(a_part.logdir, "eval.json")) as f:  # a larger goal is reached at least as often
        own = json.load(f)["per_seed"]["episode/target_reached"]
    assert all(c >= o for c, o in zip(cross["per_seed"]["episode/target_reached"], own))
    # The sampled-actions cross: the run's own env, actions sampled, as eval.py --stochastic computes it.
    with open(os.path.join(a_part.logdir, "cross-sampled.json")) as f:
        sampled = json.load(f)
    direct = evaluation.run(evaluation.checkpoint_policy(a_part.logdir), "point-mass", TOY.runs[0].config().env,
                            num_envs=16, eval_seeds=(1_000_000,), stochastic=True)
    assert sampled["actions"] == "stochastic" and cross["actions"] == "deterministic"
    assert sampled["per_seed"]["episode/distance_last10"] == pytest.approx([u["metrics"]["distance"] for u in direct.units])
    with open(os.path.join(a_part.logdir, "eval.json")) as f:  # the mode's distances differ from the samples'
        assert sampled["per_seed"]["episode/distance_last10"] != pytest.approx(json.load(f)["per_seed"]["episode/distance_last10"])
    assert ex.pending_crosses(TOY, ex.run_state(TOY, TOY.runs[0], runs_dir)) == []

    files = ex.build(selection, runs_dir, out, complete_only=True, log=lambda s: None)
    assert os.path.join(out, "toy", "runs", "a", "seeds-0-1", "cross-wide-goal.json") in files
    assert os.path.join(out, "toy", "table.md") in files
    assert os.path.join(out, "toy", "curves.png") in files or importlib.util.find_spec("matplotlib") is None
    with open(os.path.join(out, "toy", "table.json")) as f:
        data = json.load(f)
    assert [r["label"] for r in data["rows"]] == ["a", "b", "a on wide-goal", "a on sampled"]
    assert data["rows"][2]["per_seed"]["target_reached"] == pytest.approx(cross["per_seed"]["episode/target_reached"])
    assert len(data["rows"][0]["per_seed"]["target_reached"]) == 2 and data["rows"][0]["wall_seconds"] > 0
    with open(os.path.join(out, "toy", "table.md")) as f:
        text = f.read()
    assert "| paper: target reached | target reached |" in text and "| 50.0 % |" in text
    assert ex.listing(selection, runs_dir, out).splitlines()[1] == "  2 done; table built"
    assert ex.commands(selection, runs_dir) == []


def _gpu_rows_seconds(root: str, name: str) -> int:
    """One of gpu_rows.sh's reserves (REC_SECONDS, PACK_SECONDS), read from the script."""
    with open(os.path.join(root, "tools", "gpu_rows.sh")) as f:
        return int(re.search(rf"^{name}=(\d+)", f.read(), re.M).group(1))


def _gpu_rows_stand_ins(tmp_path, gpus: int, **rows):
    """(repository root, environment, arguments log) for running tools/gpu_rows.sh in `tmp_path` with stand-ins: an
    nvidia-smi listing `gpus` GPUs, and a python that notes each call's CUDA_VISIBLE_DEVICES (in args.txt.gpus)
    and arguments (in args.txt), then runs the real one."""
    bin_dir = tmp_path / "bin"
    bin_dir.mkdir()
    smi = bin_dir / "nvidia-smi"
    smi.write_text("#!/bin/bash\n" + "".join(f"echo '{i}, STAND-IN'\n" for i in range(gpus)))
    smi.chmod(0o755)
    args_log = tmp_path / "args.txt"
    (bin_dir / "python").write_text(f"#!/bin/bash\necho \"$*\" >> {args_log}\n"
                                    f"echo \"$CUDA_VISIBLE_DEVICES $4\" >> {args_log}.gpus\n"
                                    f"exec {sys.executable} \"$@\"\n")
    (bin_dir / "python").chmod(0o755)
    root = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
    env = dict(os.environ, PATH=f"{bin_dir}:{os.path.dirname(sys.executable)}:{os.environ['PATH']}",
               OUT=str(tmp_path / "out"), CALL_LOGS=str(tmp_path / "logs"), **rows)
    (tmp_path / "out").mkdir()
    return root, env, args_log


@pytest.mark.parametrize("gpus, plan", [
    (4, ["GPU 0: a b", "GPU 1: c", "GPU 2: d", "GPU 3: e f"]),
    (2, ["GPU 0: a b d", "GPU 1: c e f"]),
    (1, ["GPU 0: a b c d e f"]),
])
def test_gpu_rows_script_gives_each_gpu_its_rows(tmp_path, gpus, plan):
    """tools/gpu_rows.sh (a device call's drivers, one per GPU): row group i goes to GPU i mod the GPUs listed by
    nvidia-smi (a stand-in here). Each GPU's driver runs and leaves its log (here it stops at once: the rows are
    names no registry has, and the limit is inside the script's REC_SECONDS margin); the call still packs its logs."""
    root, env, args_log = _gpu_rows_stand_ins(tmp_path, gpus, ROWS0="a b", ROWS1="c", ROWS2="d", ROWS3="e f")
    done = subprocess.run(["bash", os.path.join(root, "tools", "gpu_rows.sh"), "1", "40"], cwd=tmp_path, env=env,
                          capture_output=True, text=True, timeout=120)
    assert done.returncode == 0, done.stderr
    assert (tmp_path / "logs" / "plan.txt").read_text().splitlines() == plan
    assert sorted(p.name for p in (tmp_path / "logs").glob("driver_*.log")) == [f"driver_g{g}.log" for g in range(gpus)]
    assert (tmp_path / "out" / "rec.tgz").is_file() and "call 1 done" in done.stdout
    # The drivers' flags parse: each got as far as its rows (an argparse error would come first). A call that is
    # not the last keeps a 20 s reserve; the last one the default, with --whole-parts.
    assert "experiment 'a' is unknown" in (tmp_path / "logs" / "driver_g0.log").read_text()
    drivers = args_log.read_text().splitlines()
    assert len(drivers) == gpus and all("--reserve 20" in a and "--whole-parts" not in a for a in drivers), drivers
    args_log.unlink()
    last = subprocess.run(["bash", os.path.join(root, "tools", "gpu_rows.sh"), "1", "40", "last"], cwd=tmp_path,
                          env=env, capture_output=True, text=True, timeout=120)
    assert last.returncode == 0 and "experiment 'a' is unknown" in (tmp_path / "logs" / "driver_g0.log").read_text()
    drivers = [a for a in args_log.read_text().splitlines() if a.startswith("-m tools.experiments run ")]
    assert drivers and all("--reserve" not in a and "--whole-parts" in a for a in drivers), drivers
    # A last call with time left after the whole-part passes (here every driver stops at once): each GPU then
    # trains a one-seed part, every pass ending the packing time before the limit, and the call packs the rows'
    # unfinished parts for the next machine, after rec.tgz; a .carry folder in the tree is unpacked first.
    args_log.unlink()
    (tmp_path / ".carry").mkdir()
    long = subprocess.run(["bash", os.path.join(root, "tools", "gpu_rows.sh"), "1", "400", "last"], cwd=tmp_path,
                          env=env, capture_output=True, text=True, timeout=300)
    assert long.returncode == 0, long.stderr
    calls = args_log.read_text().splitlines()
    assert calls[0] == "-m tools.carry_parts unpack --from .carry --runs-dir runs/experiments", calls
    assert calls[-1] == (f"-m tools.carry_parts pack --runs-dir runs/experiments --to {tmp_path / 'out' / 'carry'} "
                         "a b c d e f")
    for g in range(gpus):
        mine = [a for a in calls[1:-1] if a.split()[3:4] == [plan[g].split()[2]]]  # the driver's first row
        assert [("--whole-parts" in a, "--max-seeds 3" in a, "--reserve 20" in a) for a in mine] == [
            (True, True, False), (True, False, False), (False, False, True)], mine
        limits = [int(a.split("--time-limit ")[1].split()[0]) for a in mine]  # every pass leaves the packing time
        kept = _gpu_rows_seconds(root, "REC_SECONDS") + _gpu_rows_seconds(root, "PACK_SECONDS")
        assert 400 - kept - 10 <= limits[0] and all(t <= 400 - kept for t in limits), limits
    assert "unknown" in (tmp_path / "logs" / "pack.log").read_text()
    with tarfile.open(tmp_path / "out" / "rec.tgz") as tar:  # written before the pack began
        names = tar.getnames()
    assert any(n.endswith("logs/driver_g0_2.log") for n in names) and not any(n.endswith("/pack.log") for n in names)
    without_rows = subprocess.run(["bash", os.path.join(root, "tools", "gpu_rows.sh"), "1", "40"], cwd=tmp_path,
                                  env={k: v for k, v in env.items() if k != "ROWS0"}, capture_output=True, text=True)
    assert without_rows.returncode == 2 and "usage" in without_rows.stderr


@pytest.mark.parametrize("gpus, rows, plan, drivers", [
    (4, dict(ROWS0="a", ROWS1="c", ROWS2="", ROWS3="e"), ["GPU 0,2: a", "GPU 1: c", "GPU 3: e"],
     ["0,2 a", "1 c", "3 e"]),
    (4, dict(ROWS0="a", ROWS1="c", ROWS2="", ROWS3=""), ["GPU 0,2: a", "GPU 1,3: c"], ["0,2 a", "1,3 c"]),
    (3, dict(ROWS0="a", ROWS1="c", ROWS2=""), ["GPU 0,2: a", "GPU 1: c"], ["0,2 a", "1 c"]),
    (2, dict(ROWS0="a", ROWS1="", ROWS2="d"), ["GPU 0: a d", "GPU 1:"], ["0 a"]),
])
def test_gpu_rows_script_lends_an_empty_groups_gpu(tmp_path, gpus, rows, plan, drivers):
    """tools/gpu_rows.sh: the GPU of an empty row group i >= 2 joins group i - 2's driver (CUDA_VISIBLE_DEVICES
    names both, so its `--parallel` trains a part on each); with two GPUs nothing is lent, and a GPU whose groups
    are all empty runs no driver."""
    root, env, args_log = _gpu_rows_stand_ins(tmp_path, gpus, **rows)
    done = subprocess.run(["bash", os.path.join(root, "tools", "gpu_rows.sh"), "1", "40"], cwd=tmp_path, env=env,
                          capture_output=True, text=True, timeout=120)
    assert done.returncode == 0, done.stderr
    assert (tmp_path / "logs" / "plan.txt").read_text().splitlines() == plan
    seen = [a for a in (tmp_path / "args.txt.gpus").read_text().splitlines() if not a.startswith(" ")]
    assert sorted(seen) == drivers
