"""The experiment runner (tools/experiments.py, tools/experiment_launch.py's in-process part): pending parts, equal
runs trained once, recording fetched parts, part locks, cross-evaluation order, and a two-run toy experiment on the
point mass that trains, resumes after an interruption and builds its table. The registry:
tests/test_experiment_registry.py; tables on hand-made folders: tests/test_experiment_tables.py; launching through
submitit: tests/test_experiment_launch.py."""

import contextlib
import dataclasses
import importlib.util
import json
import os
import shutil
import subprocess
import sys

import pytest

from agents import driver
from agents.config import config_json
from experiment_parts import TOY, TOY_RUN, fake_cross, make_part, write_file
from tools import experiment_launch as launch
from tools import experiment_spec as spec
from tools import experiment_state as state
from tools import experiment_tables as tables
from tools import experiments as ex


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
    make_part(base, runs_dir, "first", "base", 0, 2, steps=[10240], evaluated=10240)

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
    make_part(other, runs_dir, "second", "other", 0, 1)
    assert ex.commands(state.select(["second/other"], registry), runs_dir, registry=registry)[0].endswith("--overwrite")

    # Building only the sharing experiment records the parts in the owner's record; a checkout without the
    # runs folder sees them done.
    make_part(base, runs_dir, "first", "base", 2, 1, steps=[10240], evaluated=10240)
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
    make_part(base, str(tmp_path / "rec"), "x", "y", 0, 2, evaluated=10240, config=old)
    os.makedirs(os.path.join(out, "first", "runs", "base", "seeds-0-0"))
    shutil.copytree(os.path.join(tmp_path, "rec", "x", "y", "seeds-0-1"), os.path.join(out, "first", "runs", "base", "seeds-0-2"))
    assert state.run_state(first, base, runs_dir, out, registry).status == "done"  # seeds-0-2 (changed) is covered


def test_record_copies_the_finished_parts_of_a_fetched_runs_folder(tmp_path, capsys):
    """`record --runs-dir DIR`: the done parts' config.json, eval.json and metrics.csv of the selected runs into
    the results (what a GPU machine's runs/ brings back), byte for byte; a partial part stays out."""
    runs_dir, out = str(tmp_path / "fetched"), str(tmp_path / "results")
    exp = spec.EXPERIMENTS["sac-fast"]
    run = exp.run("panda-reach-plus")
    done = make_part(run, runs_dir, "sac-fast", "panda-reach-plus", 0, 1, steps=[run.budget()], evaluated=run.budget(),
                 metrics=([2_000_000, run.budget()], 1, 280_000.0, [25.0, 380.0]))
    make_part(run, runs_dir, "sac-fast", "panda-reach-plus", 1, 1, steps=[30_000_000])  # stopped at its time limit
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
    make_part(b, runs_dir, "toy", "b", 0, 2, steps=[5120], metrics=([2560, 5120], 2, 10.0, [286.0, 256.0]))
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
        make_part(b, runs_dir, "toy", "b", first, 1, steps=[10240], evaluated=10240, metrics=([5120, 10240], 1, 10.0, [30.0, 9.0]))
        return driver.TrainResult(None, 10240, "done", config.logdir, config, None, None)

    monkeypatch.setattr(driver, "train", fake_train)
    monkeypatch.setattr(launch, "cross_evaluate", fake_cross(events))
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
    write_file(os.path.join(a_logdir, "config.json"), json.dumps(config_json(TOY.runs[0].config(a_logdir))))

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
