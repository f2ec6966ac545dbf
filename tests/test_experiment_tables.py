"""The experiment state and its tables on hand-made runs folders: timing read from metrics.csv, the listing and
commands, cross rows, partial runs, the joint speed columns and the figure."""

import dataclasses
import json
import os
import shutil

import pytest

from experiment_parts import TOY, TOY_RUN, make_part, write_file
from tools import experiment_launch as launch
from tools import experiment_spec as spec
from tools import experiment_state as state
from tools import experiment_tables as tables
from tools import experiments as ex


def test_read_timing_takes_the_speed_after_the_first_chunk(tmp_path):
    """The first chunk holds the compilation: the speed is the median after it; rows of no positive, finite
    speed (a hand-edited or corrupt file) are skipped; one chunk gives no speed."""
    rows = ["env_steps,seed,steps_per_second,wall_seconds", "2560,0,1000,12.56", "5120,0,0,1.0", "7680,0,nan,1.0",
            "10240,0,-5,1.0", "12800,0,1000,2.56", "15360,0,500,5.12"]
    write_file(str(tmp_path / "a" / "metrics.csv"), "\n".join(rows) + "\n")
    rate, wall = state.read_timing(str(tmp_path / "a"), 1)
    assert rate == 750.0
    assert wall == pytest.approx(20.24)
    write_file(str(tmp_path / "b" / "metrics.csv"), "\n".join(rows[:2]) + "\n")
    assert state.read_timing(str(tmp_path / "b"), 1) == (None, 12.56)
    assert state.read_timing(str(tmp_path / "c"), 1) == (None, 0.0)


def test_listing_and_commands_on_a_hand_made_runs_folder(tmp_path):
    runs_dir, out = str(tmp_path / "runs"), str(tmp_path / "out")
    extra = spec.Run("c", "point-mass-ppo", {**TOY_RUN, "seed": 20}, seeds=1, num_timesteps=10_240)
    changed = spec.Run("d", "point-mass-ppo", {**TOY_RUN, "seed": 30}, seeds=1, num_timesteps=10_240)
    exp = spec.Experiment("toy", TOY.title, TOY.paper_ref, TOY.runs + (extra, changed))
    a, b = exp.runs[:2]
    make_part(a, runs_dir, "toy", "a", 0, 2, steps=[10240], evaluated=10240)
    # Run b: seed 0 done on its own, seed 1 half trained (with an unfinished orbax save beside it).
    make_part(b, runs_dir, "toy", "b", 0, 1, steps=[10240], evaluated=10240)
    b1 = make_part(b, runs_dir, "toy", "b", 1, 1, steps=[5120], metrics=([2560, 5120], 1, 1000.0, [12.56, 2.56]))
    os.makedirs(os.path.join(b1, "checkpoints", "10240.orbax-checkpoint-tmp-1"))
    d = os.path.join(runs_dir, "toy", "d", "seeds-0-0")
    make_part(changed, runs_dir, "toy", "d", 0, 1, config=spec.apply_overrides(changed.config(d), {"env.dt": 0.2}))

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
    make_part(b, runs_dir, "toy", "b", 0, 1, steps=[10240], evaluated=10240)
    late = make_part(b, runs_dir, "toy", "b", 1, 1, steps=[10240], evaluated=10240)
    write_file(os.path.join(late, "cross-sampled.json"), json.dumps(
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
    new = make_part(a, runs_dir, "toy", "a", 0, 2, steps=[10240], evaluated=10240)
    write_file(os.path.join(new, "eval.json"), json.dumps({"env_steps": 10240, "eval_envs": 16, "per_seed": {
        "episode/target_reached": [0.5, 0.7], "episode/mean_joint_vel": [0.5, 0.7],
        "episode/mean_joint_acc": [10.0, 14.0]}, "source": {"eval_json": "results/a_eval.json"}}))
    make_part(b, runs_dir, "toy", "b", 0, 2, steps=[10240], evaluated=10240)  # target_reached only
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
    done = make_part(b, runs_dir, "toy", "b", 1, 1, steps=[10240], evaluated=10240, metrics=([5120, 10240], 1, 10.0, [30.0, 9.0]))
    make_part(b, runs_dir, "toy", "b", 0, 1, steps=[5120])
    write_file(os.path.join(done, "cross-sampled.json"), json.dumps(
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
    make_part(b, runs_dir, "toy", "b", 1, 1, evaluated=10240, metrics=([5120, 10240], 1, 10.0, [30.0, 9.0]),
          device="GPU (NVIDIA H100 80GB HBM3)")
    make_part(b, runs_dir, "toy", "b", 0, 1, steps=[10240], evaluated=10240, metrics=([5120, 10240], 1, 10.0, [30.0, 9.0]))
    tables.build([(exp, list(exp.runs))], runs_dir, out, registry={"toy": exp}, log=lambda s: None)
    with open(os.path.join(out, "toy", "table.md")) as f:
        lines = f.read().splitlines()
    head = next(line for line in lines if line.startswith("| run |")).split(" | ")
    by_run = {line.split(" | ")[0]: line.split(" | ") for line in lines if line.startswith("| ")}
    column = head.index("device (where training ended) |")
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
        logdir = make_part(run, runs_dir, "toy", run.name, first, 1, steps=[10240], evaluated=10240)
        value = 0.2 if first == 0 else 0.6
        write_file(os.path.join(logdir, "metrics.csv"), "env_steps,seed,steps_per_second,wall_seconds,episode/target_reached\n"
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
