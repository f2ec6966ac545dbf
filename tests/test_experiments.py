"""The experiment tools (registry, state, tables, the in-process runner and the CLI): every registered run builds a
valid config (and its train.py command parses back to it), the state listing and command list on a hand-made runs
folder, part locks, and a two-run toy experiment on the point mass that trains, resumes after an interruption and
builds its table. Launching through submitit: tests/test_experiment_launch.py."""

import contextlib
import dataclasses
import importlib.util
import json
import os
import shutil
import subprocess
import sys

import pytest

import train
from agents import presets
from agents import driver
from agents.config import config_json
from tools import experiment_launch as launch
from tools import experiment_spec as spec
from tools import experiment_state as state
from tools import experiment_tables as tables
from tools import experiments as ex

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))  # the checkout

TOY_RUN = dict(eval_envs=16, tensorboard=False, progress=False)
# point-mass-ppo trains 5,120 env steps per update: two updates per run. The runs differ in their seeds
# only, so they share one compiled program (the test takes a minute on a loaded 2-core CPU, not two).
TOY = spec.Experiment("toy", "point mass: two sets of seeds", "not in the paper", (
    spec.Run("a", "point-mass-ppo", dict(TOY_RUN), seeds=2, num_timesteps=10_240, paper=dict(target_reached=0.5)),
    spec.Run("b", "point-mass-ppo", {**TOY_RUN, "seed": 10}, seeds=2, num_timesteps=10_240),
), metrics=("target_reached", "distance", "wall_clock"), curves=("episode/target_reached",),
    cross=(spec.Cross("a", "wide-goal", {"goal_radius": 0.5}), spec.Cross("a", "sampled", {}, stochastic=True)))


@pytest.mark.parametrize("name", sorted(spec.EXPERIMENTS))
def test_registered_runs_are_valid_and_their_commands_parse_back(name):
    exp = spec.EXPERIMENTS[name]
    state.validate_experiment(exp)
    for run in exp.runs:
        logdir = os.path.join(state.RUNS_DIR, name, run.name)
        assert train.parse(run.train_args(logdir)) == run.config(logdir), run.name
        part = os.path.join(logdir, state.part_name(2, 1))
        assert train.parse(run.train_args(part, first_seed=2, seeds=1)) == run.config(part, first_seed=2, seeds=1)


def test_every_run_has_a_budget_and_a_seed_count_its_experiment_explains():
    """1 to 5 seeds a run (5 for the paper's stated numbers, 3 for curve comparisons); an experiment with rows of
    fewer than 3 says why in its note."""
    for name, exp in spec.EXPERIMENTS.items():
        for run in exp.runs:
            assert run.budget() > 0, (name, run.name)
            assert 1 <= run.seeds <= 5, (name, run.name, run.seeds)
        if any(run.seeds < 3 for run in exp.runs):
            assert "seed" in exp.note.lower(), name


def test_the_registry_spells_the_plus_observations_as_the_presets_do():
    from agents.presets import make_config
    from tools import registry_obstacles as obstacles
    from tools import registry_paper_tasks as paper_tasks

    assert make_config("ur5e-reach-ppo-plus").env.observation == paper_tasks.PLUS_OBS
    assert make_config("ur5e-reach-avoid-ppo-plus").env.observation == paper_tasks._PLUS_AVOID_OBS
    for env in ("ur5e-reach", "panda-reach"):
        assert make_config(f"{env}-sac-fast").env.observation == paper_tasks.PLUS_OBS
    for env in ("ur5e-reach-avoid", "panda-reach-avoid"):
        assert make_config(f"{env}-sac-fast").env.observation == paper_tasks._PLUS_AVOID_OBS
    assert make_config("panda-reach-avoid-ppo-moving3").env.observation == obstacles._MOVING3_OBS
    assert make_config("ur5e-reach-avoid-ppo-moving3").env.observation == obstacles._MOVING3_PLUS_OBS


@pytest.mark.parametrize("field", ["num_obstacles", "obstacle_motion", "obstacle_radius_range", "obstacle_speed_range"])
def test_the_registry_spells_the_moving_obstacles_as_the_presets_do(field):
    from agents.presets import make_config
    from tools import registry_obstacles as obstacles

    assert obstacles._MOVING3["env." + field] == getattr(make_config("ur5e-reach-avoid-ppo-moving3").env, field)


def test_every_recorded_part_still_reads_as_its_registry_run():
    """A preset edited after its runs trained must leave those rows overrides that keep their config: every part
    recorded under results/experiments (finished ones only) reads as its run's and done, not `changed` (a field a
    resume may not change) nor `partial` (a budget the override no longer pins)."""
    checked = 0
    for exp in spec.EXPERIMENTS.values():
        for run in exp.runs:
            folder = state.record_folder(os.path.join(ROOT, state.OUT_DIR), exp.name, run.name)
            for name in sorted(os.listdir(folder)) if os.path.isdir(folder) else ():
                span = state.parse_part(name)
                if span is not None:
                    part = state.part_state(run, os.path.join(folder, name), *span)
                    assert part.status == "done", (exp.name, run.name, name, part.status, part.reason)
                    checked += 1
    assert checked >= 50  # the parts recorded under results/experiments


def test_table_names_a_budget_other_than_the_presets():
    preset = presets.PRESETS["panda-reach-sac-fast"].run["num_timesteps"]
    run = spec.Run("x", "panda-reach-sac-fast", {"algo.compute_dtype": "float32", "env.observation": ("joint_pos", "ee_pos")},
                 num_timesteps=100_000_000)
    assert preset == 200_000_000
    assert tables.describe_overrides(run) == "algo.compute_dtype=float32, env.observation=joint_pos+ee_pos, num_timesteps=100M"
    assert tables.describe_overrides(dataclasses.replace(run, num_timesteps=preset)) == (
        "algo.compute_dtype=float32, env.observation=joint_pos+ee_pos")  # the preset's own budget: not repeated
    assert tables.describe_overrides(spec.Run("y", "panda-reach-sac-fast")) == ""


def test_bad_overrides_and_names_raise():
    with pytest.raises(ValueError, match="env.no_such_field"):
        spec.Run("x", "point-mass-ppo", {"env.no_such_field": 1}).config()
    with pytest.raises(ValueError, match="seeds and budget are Run fields"):
        spec.Run("x", "point-mass-ppo", {"seeds": 3}).config()
    with pytest.raises(ValueError, match="goal_radius"):
        state.validate_experiment(spec.Experiment("bad", "", "", (spec.Run("x", "point-mass-ppo", {"env.goal_radius": -1.0}),)))
    with pytest.raises(ValueError, match="registered twice"):
        spec.register(TOY, {"toy": TOY})
    with pytest.raises(ValueError, match=r"curve_groups row 'r' names runs \['a', 'zzz'\]: allowed are one or more of a, b"):
        spec.register(dataclasses.replace(TOY, curve_groups=(("r", ("a", "zzz")),)), {})
    with pytest.raises(ValueError, match=r"curve_axes=\('minutes',\) holds 'minutes': allowed are one or more of env_steps, wall_clock"):
        spec.register(dataclasses.replace(TOY, curve_axes=("minutes",)), {})
    with pytest.raises(ValueError, match=r"curve_axes=\(\) holds '\(\)'"):
        spec.register(dataclasses.replace(TOY, curve_axes=()), {})
    with pytest.raises(ValueError, match="run 'zzz' is not in experiment 'toy'"):
        state.select(["toy/zzz"], {"toy": TOY})
    with pytest.raises(ValueError, match="experiment 'zzz' is unknown"):
        state.select(["zzz"], {"toy": TOY})
    # Options another action would take are refused before anything is read.
    for argv, message in ((["list", "--time", "60"], "--time with list is meaningless: allowed is `launch`"),
                          (["build", "--max-seeds", "2"], "--max-seeds with build is meaningless: allowed is `launch` or "
                                                          "`run` or `commands`"),
                          (["run", "--executor", "local"], "--executor with run is meaningless: allowed is `launch`"),
                          (["record", "--runs-dir", "/nonexistent"], "--runs-dir='/nonexistent' is not a folder"),
                          (["launch", "--time", "0"], r"time_min=0 is impossible: allowed is a whole number >= 1"),
                          (["launch", "--slurm-arg", "account"], r"--slurm-arg='account' is invalid: allowed is KEY=VALUE"),
                          (["launch", "--executor", "local", "--wait"], "--wait with --executor local is meaningless"),
                          (["launch", "--time", "1", "--signal-delay", "60"], r"signal_delay_s=60 is impossible with "
                                                                               r"time_min=1"),
                          (["record", "--all"], "--all with record is meaningless: allowed is `commands`"),
                          (["commands", "--no-build"], "--no-build with commands is meaningless")):
        with pytest.raises(ValueError, match=message):
            ex.main(argv)
    state.validate_experiment(TOY)
    for cross, message in ((spec.Cross("zzz", "x", {}), "run 'zzz' is not in experiment 'toy'"),
                           (spec.Cross("a", "x", {"no_field": 1}), "env field 'no_field' is unknown for point-mass"),
                           (spec.Cross("a", "x", {"goal_radius": -1.0}), "goal_radius"),
                           (spec.Cross("a", "x/y", {}), "name='x/y' is invalid"),
                           (spec.Cross("a", "x", {}), r"env=\{\} with stochastic=False evaluates the run as trained again")):
        with pytest.raises(ValueError, match=message):
            state.validate_experiment(dataclasses.replace(TOY, cross=(cross,)))
    # A cross that moves obstacles under a run that observed their velocity as 0 in every episode is refused at
    # registration (its policies would read the motion through a normaliser fit to one value), not after training.
    static = spec.Run("static", "panda-reach-avoid-ppo-moving3", {"env.obstacle_motion": "static"})
    blind = spec.Run("blind", "panda-reach-avoid-ppo-moving3", {
        "env.obstacle_motion": "static", "env.observation": ("joint_pos", "ee_pos", "target_pos", "obstacle_pos")})
    avoid = spec.Experiment("avoid", "static and moving", "not in the paper", (static, blind))
    with pytest.raises(ValueError, match=r"cross 'static-on-moving': env=\{'obstacle_motion': 'linear'\} changes what "
                                         r"run 'static' observed as one value in training: obstacle_vel \(trained with "
                                         r"obstacle_motion='static', here varying\)"):
        state.validate_experiment(dataclasses.replace(avoid, cross=(spec.Cross("static", "static-on-moving",
                                                                          {"obstacle_motion": "linear"}),)))
    state.validate_experiment(dataclasses.replace(avoid, cross=(spec.Cross("blind", "blind-on-moving",
                                                                      {"obstacle_motion": "linear"}),)))
    assert spec.cli_option("algo.policy_hidden_sizes", (64, 64)) == ["--algo.policy-hidden-sizes", "64", "64"]
    assert spec.cli_option("tensorboard", False) == ["--no-tensorboard"]


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
    logdir = os.path.join(runs_dir, exp, run_name, state.part_name(first, count))
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
    """A stand-in for `state.cross_evaluate`: notes ("cross", first seed, cross name) in `events` and writes the part's
    cross-<name>.json as the real one would."""
    def cross_evaluate(run, part, cross):
        events.append(("cross", part.first, cross.name))
        path = os.path.join(part.logdir, f"cross-{cross.name}.json")
        _write(path, json.dumps({"env_steps": 10240, "eval_envs": 16, "per_seed": {"episode/target_reached": [0.5]}}))
        return path

    return cross_evaluate


def test_read_timing_takes_the_speed_after_the_first_chunk(tmp_path):
    """The first chunk holds the compilation: the speed is the median after it; rows of no positive, finite
    speed (a hand-edited or corrupt file) are skipped; one chunk gives no speed."""
    rows = ["env_steps,seed,steps_per_second,wall_seconds", "2560,0,1000,12.56", "5120,0,0,1.0", "7680,0,nan,1.0",
            "10240,0,-5,1.0", "12800,0,1000,2.56", "15360,0,500,5.12"]
    _write(str(tmp_path / "a" / "metrics.csv"), "\n".join(rows) + "\n")
    rate, wall = state.read_timing(str(tmp_path / "a"), 1)
    assert rate == 750.0
    assert wall == pytest.approx(20.24)
    _write(str(tmp_path / "b" / "metrics.csv"), "\n".join(rows[:2]) + "\n")
    assert state.read_timing(str(tmp_path / "b"), 1) == (None, 12.56)
    assert state.read_timing(str(tmp_path / "c"), 1) == (None, 0.0)


def test_listing_and_commands_on_a_hand_made_runs_folder(tmp_path):
    runs_dir, out = str(tmp_path / "runs"), str(tmp_path / "out")
    extra = spec.Run("c", "point-mass-ppo", {**TOY_RUN, "seed": 20}, seeds=1, num_timesteps=10_240)
    changed = spec.Run("d", "point-mass-ppo", {**TOY_RUN, "seed": 30}, seeds=1, num_timesteps=10_240)
    exp = spec.Experiment("toy", TOY.title, TOY.paper_ref, TOY.runs + (extra, changed))
    a, b = exp.runs[:2]
    _part(a, runs_dir, "toy", "a", 0, 2, steps=[10240], evaluated=10240)
    # Run b: seed 0 done on its own, seed 1 half trained (with an unfinished orbax save beside it).
    _part(b, runs_dir, "toy", "b", 0, 1, steps=[10240], evaluated=10240)
    b1 = _part(b, runs_dir, "toy", "b", 1, 1, steps=[5120], metrics=([2560, 5120], 1, 1000.0, [12.56, 2.56]))
    os.makedirs(os.path.join(b1, "checkpoints", "10240.orbax-checkpoint-tmp-1"))
    d = os.path.join(runs_dir, "toy", "d", "seeds-0-0")
    _part(changed, runs_dir, "toy", "d", 0, 1, config=spec.apply_overrides(changed.config(d), {"env.dt": 0.2}))

    states = {r.name: state.run_state(exp, r, runs_dir) for r in exp.runs}
    assert {n: s.status for n, s in states.items()} == {"a": "done", "b": "partial", "c": "missing", "d": "changed"}
    assert states["b"].steps == 5120
    assert states["b"].seeds_done == 1
    part = states["b"].parts[1]
    assert (part.first, part.count, part.status, part.rate) == (1, 1, "partial", 1000.0)
    assert part.wall_seconds == pytest.approx(15.12)
    assert "dt" in states["d"].reason
    assert "seeds-0-0" in states["d"].reason
    text = ex.listing([(exp, list(exp.runs))], runs_dir, out)
    assert "1 done, 1 partial, 1 missing, 1 changed; table not built" in text
    assert "partial 1/2 seeds done, 0.00512M/0.01024M" in text
    assert "total: 61,440 env steps" in text
    assert "35,840 trained" in text  # a: 2 x 10,240, b: 10,240 + 5,120, d: nothing (changed)
    # A part whose job failed says so, with the job's error and log.
    launch.note_job(b1, job_id="42", executor="slurm", attempts=2, status="failed", error="ValueError: boom",
                    log="/x/42_0_log.err")
    text = ex.listing([(exp, list(exp.runs))], runs_dir, out)
    assert "seeds-1-1: failed in job 42: ValueError: boom (log /x/42_0_log.err)" in text
    launch.note_job(b1, status="running", error=None)
    assert "seeds-1-1: job 42 (slurm, attempt 2)" in ex.listing([(exp, list(exp.runs))], runs_dir, out)

    lines = ex.commands([(exp, list(exp.runs))], runs_dir)
    assert lines == [
        f"python train.py point-mass-ppo --logdir {b1} --seeds 1 --num-timesteps 10240 --eval-envs 16 --no-tensorboard "
        f"--no-progress --seed 11 --resume",
        f"python train.py point-mass-ppo --logdir {os.path.join(runs_dir, 'toy', 'c', 'seeds-0-0')} --seeds 1 "
        "--num-timesteps 10240 --eval-envs 16 --no-tensorboard --no-progress --seed 20"]
    fresh = ex.commands([(exp, list(exp.runs))], runs_dir, everything=True, max_seeds=1)
    assert len(fresh) == 6
    assert all("--resume" not in line for line in fresh)  # a and b as 2 x 1 seed, c, d
    # `run` records the finished parts of an experiment whose table cannot be built yet.
    recorded = tables.record([(exp, list(exp.runs))], runs_dir, out)
    assert sorted(os.path.relpath(p, out) for p in recorded) == [
        os.path.join("toy", "runs", r, part, f) for r, part in (("a", "seeds-0-1"), ("b", "seeds-0-0"))
        for f in ("config.json", "eval.json")]
    assert not state.table_built(exp, out)


def test_a_cross_row_holds_the_parts_evaluated(tmp_path):
    """A part whose checkpoints were gone before its cross-evaluation leaves the row with the other parts' seeds."""
    runs_dir = str(tmp_path / "runs")
    b = TOY.runs[1]
    exp = dataclasses.replace(TOY, cross=(spec.Cross("b", "sampled", {}, stochastic=True),))
    _part(b, runs_dir, "toy", "b", 0, 1, steps=[10240], evaluated=10240)
    late = _part(b, runs_dir, "toy", "b", 1, 1, steps=[10240], evaluated=10240)
    _write(os.path.join(late, "cross-sampled.json"), json.dumps(
        {"env_steps": 10240, "eval_envs": 16, "per_seed": {"episode/target_reached": [0.75]}}))
    st = state.run_state(exp, b, runs_dir)
    assert tables.cross_files(st, exp.cross[0], None) == {"seeds-1-1": os.path.join(late, "cross-sampled.json")}
    merged = tables.merged_evaluation(st, tables.cross_files(st, exp.cross[0], None))
    assert merged["seeds"] == 1
    assert merged["per_seed"]["episode/target_reached"] == [0.75]
    assert tables.merged_evaluation(st)["per_seed"]["episode/target_reached"] == [0.0, 0.1]  # the eval.json of both
    assert ("cross sampled: b with sampled actions: 1 of 2 parts evaluated; 1 to evaluate here (`launch` or `run`), 0 without "
            "checkpoints here") in ex.listing([(exp, [b])], runs_dir, "")
    shutil.rmtree(os.path.join(runs_dir, "toy", "b", "seeds-0-0", "checkpoints"))  # a machine that did not keep them
    assert "0 to evaluate here (`launch` or `run`), 1 without checkpoints here" in ex.listing([(exp, [b])], runs_dir, "")
    out = str(tmp_path / "out")
    tables.build_default(exp, [state.run_state(exp, r, runs_dir) for r in exp.runs], os.path.join(out, "toy"), code="test")
    with open(os.path.join(out, "toy", "table.json")) as f:
        row = json.load(f)["rows"][-1]
    assert (row["status"], row["seeds_evaluated"], row["per_seed"]["target_reached"]) == ("partly evaluated", 1, [0.75])


def test_a_table_shows_the_joint_speed_and_acceleration_means_where_evaluated(tmp_path):
    """mean_joint_vel / mean_joint_acc columns: mean ± sample std over seeds from eval.json's episode/mean_joint_* keys,
    with their own headers and decimals; an eval.json from before the env reported them leaves the cells empty."""
    runs_dir, out = str(tmp_path / "runs"), str(tmp_path / "out")
    a, b = TOY.runs
    exp = dataclasses.replace(TOY, cross=(), metrics=("target_reached", "mean_joint_vel", "mean_joint_acc"))
    state.validate_experiment(exp)
    with pytest.raises(ValueError,
                       match=r"metric 'joint_jerk' is unknown: allowed are .*mean_joint_vel, mean_joint_acc"):
        state.validate_experiment(dataclasses.replace(exp, metrics=("joint_jerk",)))
    new = _part(a, runs_dir, "toy", "a", 0, 2, steps=[10240], evaluated=10240)
    _write(os.path.join(new, "eval.json"), json.dumps({"env_steps": 10240, "eval_envs": 16, "per_seed": {
        "episode/target_reached": [0.5, 0.7], "episode/mean_joint_vel": [0.5, 0.7],
        "episode/mean_joint_acc": [10.0, 14.0]}, "source": {"eval_json": "results/a_eval.json"}}))
    _part(b, runs_dir, "toy", "b", 0, 2, steps=[10240], evaluated=10240)  # target_reached only
    tables.build([(exp, list(exp.runs))], runs_dir, out, registry={"toy": exp}, log=lambda s: None)
    with open(os.path.join(out, "toy", "table.md")) as f:
        text = f.read()
    lines = [line for line in text.splitlines() if line.startswith("| ")]
    # a's part was recorded from an earlier train.py run: the table names the eval.py file it came from
    assert "Recorded from an earlier `train.py` run (the `eval.py` evaluation of its final checkpoint): " \
           "a from results/a_eval.json." in text
    assert "| mean joint speed (rad/s) | mean joint acceleration (rad/s²) |" in lines[0]
    cells = {line.split(" | ")[0]: line.split(" | ") for line in lines}
    # after the paper's target reached and ours; sample std, and the interval of 2 seeds: their range
    assert cells["| a"][4:6] == ["0.60 ± 0.14 [0.50, 0.70]", "12.0 ± 2.8 [10.0, 14.0]"]
    assert cells["| b"][4:6] == ["", ""]
    with open(os.path.join(out, "toy", "table.json")) as f:
        rows = {r["run"]: r for r in json.load(f)["rows"]}
    assert rows["a"]["mean"]["mean_joint_acc"] == pytest.approx(12.0)
    assert "mean_joint_acc" not in rows["b"]["mean"]
    assert rows["a"]["sources"] == ["results/a_eval.json"]
    assert "sources" not in rows["b"]


def test_a_partial_run_builds_a_row_of_its_done_seeds(tmp_path):
    """A run with one of two seeds done: its row and its cross row hold that seed and say how many are planned;
    a run with no seed done stays empty."""
    runs_dir, out = str(tmp_path / "runs"), str(tmp_path / "out")
    a, b = TOY.runs
    exp = dataclasses.replace(TOY, cross=(spec.Cross("b", "sampled", {}, stochastic=True),))
    done = _part(b, runs_dir, "toy", "b", 1, 1, steps=[10240], evaluated=10240, metrics=([5120, 10240], 1, 10.0, [30.0, 9.0]))
    _part(b, runs_dir, "toy", "b", 0, 1, steps=[5120])
    _write(os.path.join(done, "cross-sampled.json"), json.dumps(
        {"env_steps": 10240, "eval_envs": 16, "per_seed": {"episode/target_reached": [0.25]}}))
    assert state.run_state(exp, b, runs_dir).status == "partial"
    assert "cross sampled: b with sampled actions: 1 of 1 parts evaluated" in ex.listing([(exp, [b])], runs_dir, "")
    written = tables.build([(exp, list(exp.runs))], runs_dir, out, registry={"toy": exp}, log=lambda s: None)
    assert os.path.join(out, "toy", "table.md") in written
    with open(os.path.join(out, "toy", "table.json")) as f:
        rows = {(r["run"], r.get("cross")): r for r in json.load(f)["rows"]}
    row, cross, empty = rows[("b", None)], rows[("b", "sampled")], rows[("a", None)]
    assert (row["status"], row["seeds_evaluated"], row["per_seed"]["target_reached"]) == ("partial", 1, [0.1])
    assert row["wall_seconds"] == pytest.approx(39.0)
    assert (cross["status"], cross["seeds_evaluated"], cross["per_seed"]["target_reached"]) == ("partly evaluated", 1, [0.25])
    assert empty["status"] == "missing"
    assert "per_seed" not in empty
    with open(os.path.join(out, "toy", "table.md")) as f:
        table = f.read()
    assert table.count("| 1 x 16 (2 planned) |") == 2
    assert "| not done (missing) | 2 x - |" in table
    assert "device" not in table  # no eval.json names one: no device column
    # A device named by one part's eval.json: the row says which (and for how many of its seeds); a cross row,
    # evaluated elsewhere, has no training device.
    _part(b, runs_dir, "toy", "b", 1, 1, evaluated=10240, metrics=([5120, 10240], 1, 10.0, [30.0, 9.0]),
          device="GPU (NVIDIA H100 80GB HBM3)")
    _part(b, runs_dir, "toy", "b", 0, 1, steps=[10240], evaluated=10240, metrics=([5120, 10240], 1, 10.0, [30.0, 9.0]))
    tables.build([(exp, list(exp.runs))], runs_dir, out, registry={"toy": exp}, log=lambda s: None)
    with open(os.path.join(out, "toy", "table.md")) as f:
        lines = f.read().splitlines()
    head = next(line for line in lines if line.startswith("| run |")).split(" | ")
    by_run = {line.split(" | ")[0]: line.split(" | ") for line in lines if line.startswith("| ")}
    column = head.index("device (training's last call) |")
    assert by_run["| b"][column] == "GPU (NVIDIA H100 80GB HBM3) (1 of 2) |"
    assert by_run["| b on sampled"][column] == " |"
    assert not tables.build([(exp, list(exp.runs))], runs_dir, str(tmp_path / "other"), complete_only=True,
                        registry={"toy": exp}, log=lambda s: None)


def test_the_figure_draws_each_group_of_runs_on_its_own_row_against_both_axes(tmp_path, monkeypatch):
    """curve_groups: one row of panels per group (its runs drawn together), a panel per curve and axis; each line
    the mean over the run's seeds (hand-made logs: 0.2 and 0.6 at 5,120 steps) against env steps or against the
    running sum of the chunk times."""
    runs_dir, out = str(tmp_path / "runs"), str(tmp_path / "out")
    a, b = TOY.runs
    c = spec.Run("c", "point-mass-ppo", {**TOY_RUN, "seed": 20}, seeds=1, num_timesteps=10_240)
    exp = dataclasses.replace(TOY, runs=(a, b, c), cross=(), curves=("episode/target_reached",),
                              curve_groups=(("first", ("a", "c")), ("second", ("b",))),
                              curve_axes=("env_steps", "wall_clock"))
    spec.register(exp, {})
    for run, first in ((a, 0), (a, 1), (b, 0), (b, 1), (c, 0)):
        logdir = _part(run, runs_dir, "toy", run.name, first, 1, steps=[10240], evaluated=10240)
        value = 0.2 if first == 0 else 0.6
        _write(os.path.join(logdir, "metrics.csv"), "env_steps,seed,steps_per_second,wall_seconds,episode/target_reached\n"
               f"5120,{first},100,51.2,{value}\n10240,{first},100,51.2,{value + 0.1}\n"
               # c's part also logs a seed beyond c's one (as a part shared with a larger run): not drawn for c
               + ("5120,1,100,51.2,0.9\n10240,1,100,51.2,0.9\n" if run is c else ""))
    states = [state.run_state(exp, r, runs_dir) for r in exp.runs]
    from tools import plots

    drawn = {}

    def spy(*args, **kwargs):
        fig = real_grid(*args, **kwargs)
        drawn.update({ax.get_title(): {l.get_label(): list(l.get_ydata()) for l in ax.get_lines()} for ax in fig.axes})
        return fig

    real_grid = plots.curve_grid
    monkeypatch.setattr(plots, "curve_grid", spy)
    path = tables.training_figure(exp, states, os.path.join(out, "curves.png"))
    monkeypatch.undo()
    assert path
    assert os.path.isfile(path)
    assert drawn["first: " + plots.CURVE_METRICS["episode/target_reached"]]["c (1 seed)"] == pytest.approx([0.2, 0.3])

    groups = {"first": {"a": [p.logdir for p in states[0].done_parts], "c": [states[2].done_parts[0].logdir]},
              "second": {"b": [p.logdir for p in states[1].done_parts]}}
    fig = plots.curve_grid(groups, ["episode/target_reached"], ("env_steps", "wall_clock"))
    assert [ax.get_title() for ax in fig.axes] == ["first: " + plots.CURVE_METRICS["episode/target_reached"]] * 2 + [
        "second: " + plots.CURVE_METRICS["episode/target_reached"]] * 2
    assert [ax.get_xlabel() for ax in fig.axes] == [plots.X_AXES["env_steps"], plots.X_AXES["wall_clock"]] * 2
    line_a, line_c = fig.axes[0].get_lines()
    assert list(line_a.get_xdata()) == [5120, 10240]
    assert list(line_a.get_ydata()) == pytest.approx([0.4, 0.5])
    assert line_a.get_label() == "a (2 seeds)"
    # Without `keep`, curve_grid draws every seed its logs hold: c's shared part's seed 1 too.
    assert list(line_c.get_ydata()) == pytest.approx([0.55, 0.6])
    assert line_c.get_label() == "c (2 seeds)"
    assert list(fig.axes[1].get_lines()[0].get_xdata()) == pytest.approx([51.2, 102.4])
    # One legend per row, right of the row's panels and level with them: it covers no curve and squeezes no panel.
    assert [[t.get_text() for t in legend.get_texts()] for legend in fig.legends] == [["a (2 seeds)", "c (2 seeds)"],
                                                                                      ["b (2 seeds)"]]
    renderer = fig.canvas.get_renderer()
    for legend, last_panel in zip(fig.legends, (fig.axes[1], fig.axes[3])):
        box, panel = legend.get_window_extent(renderer), last_panel.get_window_extent(renderer)
        assert box.x0 > panel.x1
        assert panel.y0 < (box.y0 + box.y1) / 2 < panel.y1
    with pytest.raises(ValueError, match=r"holds 'minutes': allowed are env_steps, wall_clock"):
        plots.curve_grid(groups, ["episode/target_reached"], ("minutes",))
    from tools.experiment_spec import CURVE_AXES

    assert CURVE_AXES == tuple(plots.X_AXES)  # the registry (standard library only) spells plots' axes


def test_pending_parts_split_the_missing_seeds():
    run = spec.Run("r", "point-mass-ppo", seeds=5, num_timesteps=10_240)
    part = lambda first, count, status, steps=0: state.PartState(f"f/{state.part_name(first, count)}", first, count, status,
                                                              steps, 10_240)
    st = state.RunState("e", run, "f", "partial", 0, 10_240, [part(0, 2, "done", 10_240), part(3, 1, "partial", 5_120)])
    assert [(p.first, p.count, p.steps) for p in state.pending_parts(st)] == [(3, 1, 5_120), (2, 1, 0), (4, 1, 0)]
    st.parts = [part(1, 1, "done", 10_240)]
    assert [(p.first, p.count) for p in state.pending_parts(st)] == [(0, 1), (2, 3)]
    assert [(p.first, p.count) for p in state.pending_parts(st, max_seeds=2)] == [(0, 1), (2, 2), (4, 1)]
    assert state.pending_parts(st, max_seeds=2)[1].logdir == os.path.join("f", "seeds-2-3")
    assert state.parse_part("seeds-2-3") == (2, 2)
    assert state.parse_part("seeds-3-2") is None
    assert state.parse_part("ckpt") is None
    with pytest.raises(ValueError, match="--max-seeds=0"):
        ex.main(["list", "--max-seeds", "0"])


def test_equal_runs_train_once_and_the_record_keeps_finished_parts(tmp_path):
    runs_dir, out = str(tmp_path / "runs"), str(tmp_path / "out")
    base = spec.Run("base", "point-mass-ppo", dict(TOY_RUN), seeds=2, num_timesteps=10_240)
    same = spec.Run("same", "point-mass-ppo", dict(TOY_RUN), seeds=3, num_timesteps=10_240, label="the same config")
    other = spec.Run("other", "point-mass-ppo", {**TOY_RUN, "env.goal_radius": 0.2}, seeds=1, num_timesteps=10_240)
    first = spec.Experiment("first", "", "", (base,), metrics=("target_reached",), curves=())
    second = spec.Experiment("second", "", "", (same, other), metrics=("target_reached",), curves=())
    registry = {"first": first, "second": second}
    assert state.storage(second, same, registry) == ("first", "base")
    assert state.storage(second, other, registry) == ("second", "other")
    assert state.storage(second, same, {"second": second}) == ("second", "same")  # not registered together: its own
    apart = dataclasses.replace(same, shares=False)  # the same config on a task the code has changed since
    second_apart = spec.Experiment("second", "", "", (apart, other), metrics=("target_reached",), curves=())
    later = spec.Run("later", "point-mass-ppo", dict(TOY_RUN), seeds=1, num_timesteps=10_240)
    third = spec.Experiment("third", "", "", (later,), metrics=("target_reached",), curves=())
    changed = {"first": first, "second": second_apart, "third": third}
    assert state.storage(second_apart, apart, changed) == ("second", "same")
    assert state.storage(third, later, changed) == ("second", "same")  # the new task's folder, not the first's
    _part(base, runs_dir, "first", "base", 0, 2, steps=[10240], evaluated=10240)

    st = state.run_state(second, same, runs_dir, out, registry)
    assert st.shared == "first/base"
    assert st.folder == os.path.join(runs_dir, "first", "base")
    assert st.status == "partial"
    assert st.seeds_done == 2
    assert [p.logdir for p in state.pending_parts(st)] == [os.path.join(runs_dir, "first", "base", "seeds-2-2")]
    selection = state.select(None, registry)
    text = ex.listing(selection, runs_dir, out, registry)
    assert "[trains in first/base]" in text
    assert "total: 40,960 env steps" in text  # 3 x 10,240 once + 1 x 10,240
    lines = ex.commands(selection, runs_dir, registry=registry)
    assert len(lines) == 2
    assert "seeds-2-2 --seeds 1" in lines[0]
    assert "--seed 2" in lines[0]
    # On an empty folder the run needing the most seeds plans the shared folder's parts: no seed twice.
    fresh = ex.commands(selection, str(tmp_path / "none"), max_seeds=2, registry=registry)
    assert [line.split("--logdir ")[1].split()[0].rsplit("/", 1)[1] for line in fresh] == [
        "seeds-0-1", "seeds-2-2", "seeds-0-0"]
    # A part stopped before its first checkpoint (only config.json) is started afresh.
    _part(other, runs_dir, "second", "other", 0, 1)
    assert ex.commands(state.select(["second/other"], registry), runs_dir, registry=registry)[0].endswith("--overwrite")

    # Building only the sharing experiment records the parts in the owner's record; a checkout without the
    # runs folder sees them done.
    _part(base, runs_dir, "first", "base", 2, 1, steps=[10240], evaluated=10240)
    both = tables.record(state.select(["first", "second"], registry), str(tmp_path / "runs"), str(tmp_path / "rec2"),
                     registry=registry)
    assert len(both) == len(set(both)) == 4  # base's seeds-0-1 and seeds-2-2, recorded once though same shares them
    files = tables.build(state.select(["second"], registry), runs_dir, out, log=lambda s: None, registry=registry)
    record = os.path.join(out, "first", "runs", "base", "seeds-0-1")
    assert os.path.join(record, "eval.json") in files
    assert os.path.join(record, "config.json") in files
    assert not os.path.exists(os.path.join(out, "second", "runs"))
    with open(os.path.join(out, "second", "table.json")) as f:
        row = json.load(f)["rows"][0]
    assert row["per_seed"]["target_reached"] == pytest.approx([0.0, 0.1, 0.2])
    assert row["shared"] == "first/base"
    assert [p["seeds"] for p in row["parts"]] == ["seeds-0-1", "seeds-2-2"]
    # The owner's own table takes its 2 seeds, not the third one trained for the sharing run.
    tables.build(state.select(["first"], registry), runs_dir, out, log=lambda s: None, registry=registry)
    with open(os.path.join(out, "first", "table.json")) as f:
        row = json.load(f)["rows"][0]
    assert row["per_seed"]["target_reached"] == pytest.approx([0.0, 0.1])
    assert row["seeds_evaluated"] == 2
    elsewhere = str(tmp_path / "empty")
    assert state.run_state(first, base, elsewhere, out, registry).status == "done"
    assert state.run_state(first, base, elsewhere, None, registry).status == "missing"
    # Record against runs folder, same span: the done one counts; an outdated record part whose seeds are done
    # elsewhere does not block the run.
    shutil.rmtree(os.path.join(runs_dir, "first", "base", "seeds-0-1", "checkpoints"))
    os.remove(os.path.join(runs_dir, "first", "base", "seeds-0-1", "eval.json"))
    os.makedirs(os.path.join(runs_dir, "first", "base", "seeds-0-1", "checkpoints", "5120"))
    st = state.run_state(first, base, runs_dir, out, registry)
    assert st.status == "done"
    assert st.done_parts[0].logdir == record
    old = spec.apply_overrides(base.config(), {"env.dt": 0.2})
    _part(base, str(tmp_path / "rec"), "x", "y", 0, 2, evaluated=10240, config=old)
    os.makedirs(os.path.join(out, "first", "runs", "base", "seeds-0-0"))
    shutil.copytree(os.path.join(tmp_path, "rec", "x", "y", "seeds-0-1"), os.path.join(out, "first", "runs", "base", "seeds-0-2"))
    assert state.run_state(first, base, runs_dir, out, registry).status == "done"  # seeds-0-2 (changed) is covered


def test_record_copies_the_finished_parts_of_a_fetched_runs_folder(tmp_path, capsys):
    """`record --runs-dir DIR`: the done parts' config.json, eval.json and metrics.csv of the selected runs into
    the results (what a GPU machine's runs/ brings back), byte for byte; a partial part stays out."""
    runs_dir, out = str(tmp_path / "fetched"), str(tmp_path / "results")
    exp = spec.EXPERIMENTS["sac-fast"]
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
    assert state.run_state(exp, run, str(tmp_path / "elsewhere"), out).seeds_done == 1
    assert not os.path.exists(os.path.join(out, "sac-fast", "table.md"))  # no table: build does that


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
    lock = launch.lock_path(logdir)
    assert lock == os.path.join(runs_dir, "toy", "b", ".seeds-0-1.lock")
    calls = []

    def fake_train(config, learner_cls=None):
        with launch.part_lock(logdir) as inner:  # held by this process while it trains: a second taker is refused
            calls.append(inner)
        return driver.TrainResult(None, 5120, "stopped", config.logdir, config, None, None)

    monkeypatch.setattr(driver, "train", fake_train)
    monkeypatch.setitem(spec.EXPERIMENTS, "toy", TOY)
    selection = state.select(["toy/b"])
    out = str(tmp_path / "out")
    with _lock_held_elsewhere(lock) as holder:
        log = []
        assert not launch.run_parts(selection, runs_dir, out, log=log.append)
        assert calls == []
        assert log == [f"[toy/b seeds-0-1] left alone: another process (pid {holder}) holds its lock {lock}"], log
    assert os.path.isfile(lock)  # left behind by the killed process, holding nothing
    log = []
    assert not launch.run_parts(selection, runs_dir, out, log=log.append)  # stopped short of the budget
    assert len(calls) == 1
    assert calls[0].startswith("another process (pid ")
    assert f"pid {os.getpid()} on " in calls[0]
    assert "resuming at 5,120" in log[0], log
    with launch.part_lock(logdir) as free:  # released after training
        assert free is None


def test_each_part_is_cross_evaluated_and_recorded_before_the_next_trains(tmp_path, monkeypatch):
    """With `--max-seeds 1`, part 0's cross-evaluations (its run's and those of a run of another experiment
    sharing its folder) and its record happen before part 1 trains, so a call killed during part 1 keeps them."""
    runs_dir, out = str(tmp_path / "runs"), str(tmp_path / "out")
    b = TOY.runs[1]
    mine = dataclasses.replace(TOY, runs=(b,), cross=(spec.Cross("b", "sampled", {}, stochastic=True),))
    twin = spec.Experiment("twin", "the same run elsewhere", "", (spec.Run("b2", b.preset, dict(b.overrides), seeds=2,
                         num_timesteps=10_240),), cross=(spec.Cross("b2", "wide", {"goal_radius": 0.5}),))
    monkeypatch.setitem(spec.EXPERIMENTS, "toy", mine)
    monkeypatch.setitem(spec.EXPERIMENTS, "twin", twin)
    assert state.storage(twin, twin.runs[0]) == ("toy", "b")
    events = []

    def fake_train(config, learner_cls=None):  # trains the part to its end: checkpoint, eval.json, metrics.csv
        first = config.seed - 10
        events.append(("train", first, sorted(os.listdir(os.path.join(out, "toy", "runs", "b"))) if os.path.isdir(
            os.path.join(out, "toy", "runs", "b")) else []))
        _part(b, runs_dir, "toy", "b", first, 1, steps=[10240], evaluated=10240, metrics=([5120, 10240], 1, 10.0, [30.0, 9.0]))
        return driver.TrainResult(None, 10240, "done", config.logdir, config, None, None)

    monkeypatch.setattr(driver, "train", fake_train)
    monkeypatch.setattr(launch, "cross_evaluate", _fake_cross(events))
    assert launch.run_parts(state.select(["toy"]), runs_dir, out, max_seeds=1, log=lambda s: None)
    assert [e[:2] for e in events] == [("train", 0), ("cross", 0), ("cross", 0), ("train", 1), ("cross", 1), ("cross", 1)]
    assert {e[2] for e in events if e[0] == "cross"} == {"sampled", "wide"}
    assert events[3][2] == ["seeds-0-0"]  # part 0 recorded before part 1 trained
    assert sorted(os.listdir(os.path.join(out, "toy", "runs", "b", "seeds-0-0"))) == [
        "config.json", "cross-sampled.json", "cross-wide.json", "eval.json", "metrics.csv"]
    # Nothing is left: a second call evaluates nothing more.
    events.clear()
    assert launch.run_parts(state.select(["toy", "twin"]), runs_dir, out, log=lambda s: None)
    assert events == []


def test_toy_experiment_trains_resumes_and_builds(tmp_path, monkeypatch):
    runs_dir, out = str(tmp_path / "runs"), str(tmp_path / "out")
    monkeypatch.setitem(spec.EXPERIMENTS, "toy", TOY)
    selection = state.select(["toy"])
    assert state.run_state(TOY, TOY.runs[0], runs_dir).status == "missing"
    # Run b is stopped half way, as a job past its time limit leaves it.
    b = TOY.runs[1]
    logdir = os.path.join(runs_dir, "toy", "b", "seeds-0-1")
    assert driver.train(b.config(logdir, stop_after_steps=5120)).status == "stopped"
    assert state.run_state(TOY, b, runs_dir).status == "partial"
    # Run a was killed before its first checkpoint: config.json alone; the runner starts it afresh.
    a_logdir = os.path.join(runs_dir, "toy", "a", "seeds-0-1")
    _write(os.path.join(a_logdir, "config.json"), json.dumps(config_json(TOY.runs[0].config(a_logdir))))

    log = []
    assert launch.run_parts(selection, runs_dir, out, log=log.append)
    assert any("[toy/b seeds-0-1] resuming at 5,120" in line for line in log)
    for run in TOY.runs:
        st = state.run_state(TOY, run, runs_dir)
        assert st.status == "done"
        assert st.steps == 10_240
    with open(os.path.join(logdir, "eval.json")) as f:
        written = json.load(f)
    from agents.provenance import device_description

    assert written["env_steps"] == 10_240
    assert written["device"] == device_description() == f"CPU, {os.cpu_count()} cores"
    assert written["provenance"]["device"] == written["device"]
    assert written["provenance"]["command"].startswith("python ")

    # The cross-evaluation ran once run a was done: its policies on a 0.5 m goal, as eval.py computes it.
    a_part = state.run_state(TOY, TOY.runs[0], runs_dir).done_parts[0]
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
    assert sampled["actions"] == "stochastic"
    assert cross["actions"] == "deterministic"
    assert sampled["per_seed"]["episode/distance_last10"] == pytest.approx([u["metrics"]["distance"] for u in direct.units])
    with open(os.path.join(a_part.logdir, "eval.json")) as f:  # the mode's distances differ from the samples'
        assert sampled["per_seed"]["episode/distance_last10"] != pytest.approx(json.load(f)["per_seed"]["episode/distance_last10"])
    assert state.pending_crosses(TOY, state.run_state(TOY, TOY.runs[0], runs_dir)) == []

    files = tables.build(selection, runs_dir, out, complete_only=True, log=lambda s: None)
    assert os.path.join(out, "toy", "runs", "a", "seeds-0-1", "cross-wide-goal.json") in files
    assert os.path.join(out, "toy", "table.md") in files
    assert os.path.join(out, "toy", "curves.png") in files or importlib.util.find_spec("matplotlib") is None
    with open(os.path.join(out, "toy", "table.json")) as f:
        data = json.load(f)
    assert [r["label"] for r in data["rows"]] == ["a", "b", "a on wide-goal", "a on sampled"]
    assert data["rows"][2]["per_seed"]["target_reached"] == pytest.approx(cross["per_seed"]["episode/target_reached"])
    assert len(data["rows"][0]["per_seed"]["target_reached"]) == 2
    assert data["rows"][0]["wall_seconds"] > 0
    with open(os.path.join(out, "toy", "table.md")) as f:
        text = f.read()
    assert "| paper: target reached | target reached |" in text
    assert "| 50.0 % |" in text
    assert ex.listing(selection, runs_dir, out).splitlines()[1] == "  2 done; table built"
    assert ex.commands(selection, runs_dir) == []


def test_the_docs_recipe_for_an_experiment_registers_and_validates():
    """docs/experiments.md's "Add an experiment" block, run as written against a fresh registry."""
    with open(os.path.join(ROOT, "docs", "experiments.md")) as f:
        text = f.read()
    block = text.split("## Add an experiment", 1)[1].split("```python\n", 1)[1].split("```", 1)[0]
    registry = {}
    names = {"register": lambda exp: spec.register(exp, registry), "Experiment": spec.Experiment, "Run": spec.Run,
             "Cross": spec.Cross, "paper_row": spec.paper_row}
    exec(block, names)
    (exp,) = registry.values()
    state.validate_experiment(exp)
    assert exp.runs[0].paper == {"target_reached": 0.961, "self_collision": 0.022}  # the paper's UR5e reach PPO row
    assert exp.runs[1].budget() == 100_000_000


def test_build_with_nothing_finished_says_so_and_exits_1(tmp_path, capsys):
    code = ex.main(["build", "action-space", "--runs-dir", str(tmp_path / "none"), "--out", str(tmp_path / "out")])
    assert code == 1
    assert "nothing built: no run of action-space has a finished part" in capsys.readouterr().err
    assert not (tmp_path / "out").exists()


def test_a_part_is_refused_before_training_without_the_interval_packages(tmp_path, monkeypatch):
    """Its cross-evaluations' intervals come after the training: without rliable a part would train, then fail."""
    monkeypatch.setitem(sys.modules, "rliable.library", None)  # its import fails
    monkeypatch.setattr(driver, "train", lambda *a, **k: pytest.fail("trained before refusing"))
    monkeypatch.setitem(spec.EXPERIMENTS, "toy", TOY)
    with pytest.raises(ValueError, match="need rliable"):
        launch.train_part("toy/b", "seeds-0-1", str(tmp_path / "runs"), str(tmp_path / "out"))
