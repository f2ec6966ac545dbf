"""What train.py does with a logdir, a damaged checkpoint, a non-finite learner metric and Ctrl-C
(defects these guard against: a reused logdir lost runs, a damaged checkpoint bricked --resume, NaN metrics were kept).

Every run is the PPO point-mass probe with the same length, so the tests share one compiled program.
"""

import csv
import dataclasses
import json
import os
import re
import shutil

import jax
import jax.numpy as jnp
import numpy as np
import pytest

import train as train_cli
from agents import driver, logger, presets
from agents.checkpoint import Checkpointer
from agents.config import config_json, merge_resume_config
from agents.ppo import PPO

SHORT = 30_720  # 6 updates of the PPO probe preset (the program of tests/test_agents_learning.py's 1-seed runs)
QUIET = dict(tensorboard=False, progress=False, eval_envs=0)


def _config(logdir, **options):
    return presets.make_config("point-mass-ppo", num_timesteps=SHORT, logdir=str(logdir), **{**QUIET, **options})


def _snapshot(directory) -> dict:
    """{relative path: (size, mtime)} of every file under `directory`."""
    out = {}
    for root, _, files in os.walk(directory):
        for name in files:
            path = os.path.join(root, name)
            out[os.path.relpath(path, directory)] = (os.path.getsize(path), os.path.getmtime(path))
    return out


@pytest.fixture(scope="module")
def earlier_run(tmp_path_factory):
    """A finished run with checkpoints at 10240, 20480 and 30720 env steps."""
    logdir = tmp_path_factory.mktemp("earlier") / "run"
    driver.train(_config(logdir, checkpoint_every=2 * 5120, log_every=5120))
    return logdir


@pytest.fixture
def no_compile(monkeypatch):
    monkeypatch.setattr(driver, "build_programs", lambda *a, **k: pytest.fail("compiled despite bad input"))


# ------------------------------------------------------------------------------------------------
# 1. A logdir holding an earlier run


def test_logdir_of_an_earlier_run_is_refused_before_anything_is_written(earlier_run, no_compile):
    before = _snapshot(earlier_run)
    with pytest.raises(ValueError, match=r"logdir='.*run' holds an earlier run \(checkpoints, config.json, "
                                         r"metrics.csv\): allowed are resume=True \(--resume\) .* a new logdir \(--logdir\), "
                                         r"or overwrite=True \(--overwrite\)"):
        driver.train(_config(earlier_run))
    assert _snapshot(earlier_run) == before


def test_overwrite_removes_the_earlier_run_first(earlier_run, tmp_path):
    logdir = tmp_path / "run"
    shutil.copytree(earlier_run, logdir)
    (logdir / "notes.txt").write_text("mine")  # not the run's: kept
    result = driver.train(_config(logdir, overwrite=True, log_every=SHORT))
    assert result.status == "done"
    assert Checkpointer(str(logdir / "checkpoints")).manager.all_steps() == [SHORT]  # the old 10240, 20480 are gone
    assert len((logdir / "metrics.csv").read_text().splitlines()) == 1 + 1  # header + this run's one row
    assert (logdir / "notes.txt").read_text() == "mine"
    assert json.loads((logdir / "config.json").read_text())["overwrite"] is True


def test_overwrite_leaves_no_aside_folder_after_a_finished_run(earlier_run, tmp_path):
    logdir = tmp_path / "run"
    shutil.copytree(earlier_run, logdir)
    driver.train(_config(logdir, overwrite=True, log_every=SHORT))
    assert sorted(p.name for p in logdir.iterdir() if p.name.startswith(".")) == []


def test_overwrite_whose_new_run_fails_to_build_keeps_the_earlier_run(earlier_run, tmp_path, monkeypatch):
    logdir = tmp_path / "run"
    shutil.copytree(earlier_run, logdir)
    before = _snapshot(logdir)
    monkeypatch.setattr(driver, "build_programs", lambda *a, **k: (_ for _ in ()).throw(RuntimeError("no memory")))
    with pytest.raises(RuntimeError, match="no memory"):
        driver.train(_config(logdir, overwrite=True))
    assert _snapshot(logdir) == before  # every file back, unchanged, and no aside folder left


def test_overwrite_whose_new_run_diverges_before_a_checkpoint_keeps_the_earlier_run(earlier_run, tmp_path, monkeypatch):
    logdir = tmp_path / "run"
    shutil.copytree(earlier_run, logdir)
    before = _snapshot(logdir)
    monkeypatch.setattr(driver, "nonfinite_learner_metrics", lambda metrics: [min(k for k in metrics if k.startswith("loss/"))])
    with pytest.raises(driver.NonFiniteLossError):
        driver.train(_config(logdir, overwrite=True))
    assert _snapshot(logdir) == before


def test_rows_logged_after_the_last_checkpoint_are_dropped_on_resume(earlier_run, tmp_path):
    """A run killed after its checkpoint at SHORT had logged rows beyond it; the resume logs those steps again,
    so metrics.csv ends with each (step, seed) once."""
    logdir = tmp_path / "run"
    shutil.copytree(earlier_run, logdir)
    with open(logdir / "metrics.csv") as f:
        header, *rows = list(csv.reader(f))
    beyond = [[str(SHORT + 5120) if name == "env_steps" else value for name, value in zip(header, rows[-1])]]
    with open(logdir / "metrics.csv", "a", newline="") as f:
        csv.writer(f).writerows(beyond)  # what the killed process logged after its last checkpoint
    driver.train(presets.make_config("point-mass-ppo", num_timesteps=SHORT + 15360, logdir=str(logdir), resume=True,
                                     log_every=5120, **QUIET))
    with open(logdir / "metrics.csv") as f:
        logged = [(r["env_steps"], r["seed"]) for r in csv.DictReader(f)]
    assert len(logged) == len(set(logged))


def test_cut_rows_after_keeps_the_rows_up_to_the_step(tmp_path):
    path = tmp_path / "metrics.csv"
    path.write_text("env_steps,seed,loss\n10,0,1.0\n10,1,1.1\n20,0,0.9\n20,1,0.8\n30,0,0.7\n30,1,0.6\n")
    assert logger.cut_rows_after(str(path), 20) == 2
    assert path.read_text().splitlines() == ["env_steps,seed,loss", "10,0,1.0", "10,1,1.1", "20,0,0.9", "20,1,0.8"]


def test_cut_rows_after_leaves_a_file_without_later_rows_untouched(tmp_path):
    path = tmp_path / "metrics.csv"
    path.write_text("env_steps,seed,loss\n10,0,1.0\n")
    before = os.path.getmtime(path)
    assert logger.cut_rows_after(str(path), 10) == 0
    assert os.path.getmtime(path) == before


def test_overwrite_and_resume_together_are_refused(tmp_path, no_compile):
    with pytest.raises(ValueError, match=r"overwrite=True is invalid with resume=True"):
        train_cli.main(["point-mass-ppo", "--logdir", str(tmp_path), "--resume", "--overwrite"])


def test_resume_of_a_missing_directory_creates_nothing(tmp_path, no_compile):
    with pytest.raises(ValueError, match=r"resume=True but logdir=.* holds no checkpoint"):
        driver.train(_config(tmp_path / "missing", resume=True))
    assert not (tmp_path / "missing").exists()


def test_explicit_fields_names_the_typed_options():
    args = ["--algo.learning-rate", "3e-4", "--no-progress", "--env.goal-radius=0.05", "--seeds", "2",
            "--algo.target-entropy", "-3", "--algo.no_layer_norm", "--env.observation", "joint_pos", "ee_pos"]
    assert train_cli.explicit_fields(args) == {"algo.learning_rate", "progress", "env.goal_radius", "seeds",
                                               "algo.target_entropy", "algo.layer_norm", "env.observation"}


def test_resume_takes_the_untyped_options_from_the_stored_run(tmp_path, no_compile):
    # A run trained with a changed learning rate, goal radius and length: resuming it with the preset alone
    # continues it with those values (before, the preset's own values were refused as differing).
    base = presets.make_config("point-mass-ppo", logdir=str(tmp_path))
    stored = dataclasses.replace(base, num_timesteps=40960, seeds=2, log_every=5120, tensorboard=False,
                                 stop_after_steps=20480, algo=dataclasses.replace(base.algo, learning_rate=1e-2),
                                 env=dataclasses.replace(base.env, goal_radius=0.07))
    (tmp_path / "config.json").write_text(json.dumps(config_json(stored)))
    resumed = train_cli.parse(["point-mass-ppo", "--logdir", str(tmp_path), "--resume", "--no-progress"])
    assert (resumed.algo.learning_rate, resumed.env.goal_radius, resumed.num_timesteps, resumed.seeds) == (1e-2, 0.07, 40960, 2)
    assert (resumed.log_every, resumed.tensorboard) == (5120, False)  # the run's logging ...
    assert (resumed.progress, resumed.resume, resumed.stop_after_steps) == (False, True, 0)  # ... this call's own
    assert merge_resume_config(resumed, stored, done_steps=20480) == resumed
    # A typed option is kept, so that the driver refuses it when it differs from the stored run ...
    typed = train_cli.parse(["point-mass-ppo", "--logdir", str(tmp_path), "--resume", "--algo.learning-rate", "0.003"])
    assert typed.algo.learning_rate == 0.003
    assert typed.env.goal_radius == 0.07
    with pytest.raises(ValueError, match=r"algo.learning_rate=0.003 differs from the checkpoint's 0.01"):
        merge_resume_config(typed, stored, done_steps=20480)
    # ... except num_timesteps, which a resume may raise.
    longer = train_cli.parse(["point-mass-ppo", "--logdir", str(tmp_path), "--resume", "--num-timesteps", "61440"])
    assert longer.num_timesteps == 61440
    assert longer.algo.learning_rate == 1e-2
    # Another preset's run is refused, before anything compiles.
    with pytest.raises(ValueError, match=r"preset='point-mass-sac' differs from the resumed run's 'point-mass-ppo': "
                                         r"allowed on --resume is the run's own preset"):
        train_cli.parse(["point-mass-sac", "--logdir", str(tmp_path), "--resume"])
    (tmp_path / "config.json").write_text("{not json")
    with pytest.raises(ValueError, match=r"config.json cannot be read as a run's config"):
        train_cli.parse(["point-mass-ppo", "--logdir", str(tmp_path), "--resume"])


def test_resume_with_fewer_timesteps_than_done_is_refused_and_a_change_is_noted(earlier_run, no_compile):
    before = _snapshot(earlier_run)
    with pytest.raises(ValueError, match=rf"num_timesteps=20480 is below the checkpoint's {SHORT} env steps .* "
                                         rf"allowed on --resume is num_timesteps >= {SHORT - 5120 + 1} \(runs end on "
                                         r"whole updates of 5120 env steps\)"):
        driver.train(dataclasses.replace(_config(earlier_run, resume=True), num_timesteps=20480))
    assert _snapshot(earlier_run) == before
    saved = _config(earlier_run)
    with pytest.warns(UserWarning, match=rf"num_timesteps=40960 differs from the checkpoint's {SHORT}: .* config.json"):
        merged = merge_resume_config(dataclasses.replace(saved, num_timesteps=40960), saved, done_steps=SHORT)
    assert merged.num_timesteps == 40960


def test_a_run_whose_num_timesteps_is_not_whole_updates_resumes_with_its_own_config(earlier_run):
    """A run of 28,000 env steps ends after 6 updates of 5,120 (30,720 steps): its own num_timesteps is allowed."""
    saved = dataclasses.replace(_config(earlier_run), num_timesteps=28_000)
    assert merge_resume_config(saved, saved, done_steps=SHORT).num_timesteps == 28_000


def test_a_changed_field_is_named_before_num_timesteps_on_resume(earlier_run):
    saved = _config(earlier_run)
    changed = dataclasses.replace(saved, num_timesteps=10240, algo=dataclasses.replace(saved.algo, learning_rate=1e-3))
    with pytest.raises(ValueError, match=r"algo.learning_rate=0.001 differs from the checkpoint's"):
        merge_resume_config(changed, saved, done_steps=SHORT)


@pytest.mark.parametrize("where, message", [
    ("file", r"logdir='.*' is a file: allowed is a directory"),
    ("under_file", r"logdir='.*' cannot be created \(.*\): allowed is a directory you can write to"),
    ("read_only", r"logdir='/sys/.*' cannot be created \(.*\): allowed is a directory you can write to"),
])
def test_unusable_logdir_is_a_one_line_error(where, message, tmp_path, no_compile, capsys):
    (tmp_path / "file").write_text("x")
    logdir = {"file": tmp_path / "file", "under_file": tmp_path / "file" / "run",
              "read_only": "/sys/reach_avoid_test_run"}[where]
    assert train_cli.cli(["point-mass-ppo", "--logdir", str(logdir), "--no-progress"]) == 2
    err = capsys.readouterr().err
    assert err.startswith("error: "), err
    assert err.count("\n") == 1, err
    assert re.search(message, err), err


# ------------------------------------------------------------------------------------------------
# 3. A damaged newest checkpoint


def _damage(step_dir, how):
    if how == "array":  # truncate the largest array file
        files = [p for p in step_dir.joinpath("state").rglob("*") if p.is_file()]
        biggest = max(files, key=lambda p: p.stat().st_size)
        biggest.write_bytes(biggest.read_bytes()[: biggest.stat().st_size // 2])
    else:  # truncate a metadata file
        meta = step_dir / "config" / "metadata"
        meta.write_text(meta.read_text()[:10])


@pytest.mark.parametrize("how", ["array", "metadata"])
def test_resume_falls_back_to_the_newest_intact_checkpoint(earlier_run, tmp_path, how):
    logdir = tmp_path / "run"
    shutil.copytree(earlier_run, logdir)
    _damage(logdir / "checkpoints" / str(SHORT), how)
    _damage(logdir / "checkpoints" / "20480", how)
    with pytest.warns(UserWarning, match=rf"checkpoint .*checkpoints/{SHORT} is damaged .* moved to .*corrupt_checkpoints"):
        result = driver.train(_config(logdir, resume=True, checkpoint_every=2 * 5120, log_every=5120))
    assert result.status == "done"
    assert result.env_steps == SHORT
    assert sorted(os.listdir(logdir / "corrupt_checkpoints")) == ["20480", str(SHORT)]
    assert Checkpointer(str(logdir / "checkpoints")).manager.all_steps() == [10240, 20480, SHORT]  # saved again


def test_a_checkpoint_whose_env_states_another_env_wrote_resumes_its_learner(earlier_run, tmp_path, monkeypatch):
    """Env states saved by another version of the env (here: one metric more in this one) do not restore; the
    learner does, by tree path (its leaves equal the full restore's): a learner-only copy can be made, and the
    run resumes from that step with fresh episodes and a warning, instead of setting the checkpoint aside as
    damaged."""
    from envs.point_mass import PointMass

    logdir = tmp_path / "run"
    shutil.copytree(earlier_run, logdir)
    config = _config(logdir, checkpoint_every=2 * 5120, log_every=5120)
    ckpt = Checkpointer(str(logdir / "checkpoints"))
    programs = driver.programs_for(config)
    full = ckpt.restore(SHORT, programs.abstract_state)[0]
    learner = ckpt.restore_matching(SHORT, driver._learner_only(programs.abstract_state, programs.learner))
    for a, b in zip(jax.tree.leaves(learner.learner), jax.tree.leaves(full.learner)):
        np.testing.assert_array_equal(a, b)
    np.testing.assert_array_equal(learner.updates, full.updates)
    assert (np.asarray(full.updates) > 0).all()
    ckpt.close()
    rows_before = len((logdir / "metrics.csv").read_text().splitlines())
    original = PointMass._metrics
    monkeypatch.setattr(PointMass, "_metrics", lambda self, d, r, n: {**original(self, d, r, n), "extra": d})
    # A learner-only copy (small enough to move a run between machines) of the old-layout checkpoint, under the new env.
    assert driver.learner_only_checkpoint(str(logdir), str(tmp_path / "carried")) == SHORT
    carried = Checkpointer(str(tmp_path / "carried" / "checkpoints"))
    copy = carried.restore_matching(SHORT, driver._learner_only(programs.abstract_state, programs.learner))
    carried.close()
    for a, b in zip(jax.tree.leaves(copy.learner), jax.tree.leaves(full.learner)):
        np.testing.assert_array_equal(a, b)
    with pytest.warns(UserWarning, match=rf"checkpoint .*checkpoints/{SHORT}: its env states do not fit this env's"):
        result = driver.train(presets.make_config("point-mass-ppo", num_timesteps=SHORT + 10240, logdir=str(logdir),
                                                  resume=True, log_every=5120, **QUIET))
    assert result.status == "done"
    assert result.env_steps == SHORT + 10240
    assert not (logdir / "corrupt_checkpoints").exists()
    assert len((logdir / "metrics.csv").read_text().splitlines()) == rows_before + 2  # 2 rows after SHORT


@pytest.mark.parametrize("rebuild", ["export", "learner_only"])
def test_a_checkpoint_with_an_impossible_stored_config_is_refused_before_compiling(earlier_run, tmp_path, no_compile,
                                                                                    rebuild):
    """A checkpoint's config (edited by hand, or from an older version) is checked before its programs are built."""
    logdir = tmp_path / "run"
    shutil.copytree(earlier_run, logdir)
    stored = logdir / "checkpoints" / str(SHORT) / "config" / "metadata"
    config = json.loads(stored.read_text())
    config["env"]["goal_radius"] = -1.0
    stored.write_text(json.dumps(config))
    with pytest.raises(ValueError, match=r"goal_radius=-1.0 is invalid"):
        if rebuild == "export":
            driver.export_checkpoint(str(logdir / "checkpoints" / str(SHORT)))
        else:
            driver.learner_only_checkpoint(str(logdir), str(tmp_path / "learner_only"))


def test_resume_with_no_intact_checkpoint_names_them(earlier_run, tmp_path, capsys):
    logdir = tmp_path / "run"
    shutil.copytree(earlier_run, logdir)
    for step in (10240, 20480, SHORT):
        _damage(logdir / "checkpoints" / str(step), "metadata")
    code = train_cli.cli(["point-mass-ppo", "--logdir", str(logdir), "--resume", "--num-timesteps", str(SHORT),
                          "--no-progress", "--no-tensorboard"])
    err = capsys.readouterr().err
    assert code == 2, err
    assert err.count("\n") == 1, err
    assert err.startswith("error: "), err
    assert "holds no intact checkpoint" in err
    assert f"checkpoints/{SHORT}: " in err
    assert "checkpoints/10240: " in err


# ------------------------------------------------------------------------------------------------
# 9. Every learner metric is guarded


class _InfGradPPO(PPO):
    """PPO whose gradient norm becomes infinite from its 4th update on (its losses stay finite)."""

    def update(self, state, batch, key, par):
        state, metrics = super().update(state, batch, key, par)
        return state, {**metrics, "optim/grad_norm": jnp.where(state.updates >= 4, jnp.inf, metrics["optim/grad_norm"])}


class _NaNKLPPO(PPO):
    """PPO whose approximate KL is NaN from the first update on."""

    def update(self, state, batch, key, par):
        state, metrics = super().update(state, batch, key, par)
        return state, {**metrics, "policy/approx_kl": jnp.full_like(metrics["policy/approx_kl"], jnp.nan)}


def test_nonfinite_learner_metric_stops_the_run_before_its_checkpoint(tmp_path):
    config = _config(tmp_path / "inf", checkpoint_every=2 * 5120, log_every=5120)
    with pytest.raises(driver.NonFiniteLossError, match=r"optim/grad_norm became \[inf\] .*env step 20480.*"
                                                        r"last good checkpoint \(env step 10240\)"):
        driver.train(config, learner_cls=_InfGradPPO)
    assert Checkpointer(str(tmp_path / "inf" / "checkpoints")).manager.all_steps() == [10240]


def test_nonfinite_metric_in_the_first_chunk_leaves_no_run_directory(tmp_path):
    config = _config(tmp_path / "nan", checkpoint_every=2 * 5120, log_every=5120)
    with pytest.raises(driver.NonFiniteLossError, match=r"policy/approx_kl became \[nan\] .* No checkpoint had been "
                                                        r"saved yet, so none is kept; the run directory .* was removed"):
        driver.train(config, learner_cls=_NaNKLPPO)
    assert not (tmp_path / "nan").exists()


def test_episode_metrics_may_be_nan():
    """A chunk in which no episode ended reports NaN episode averages: that is not a broken learner."""
    metrics = {"episode/return": np.array([np.nan]), "episodes": np.array([0.0]), "loss/total": np.array([1.0])}
    assert driver.nonfinite_learner_metrics(metrics) == []
    assert driver.nonfinite_learner_metrics({**metrics, "sac/alpha": np.array([np.inf])}) == ["sac/alpha"]


# ------------------------------------------------------------------------------------------------
# 10. Ctrl-C


def test_ctrl_c_saves_a_checkpoint_and_exits_130(tmp_path, monkeypatch, capsys):
    """A Ctrl-C during the first chunk (the handler's flag set at once): checkpoint, then exit 130."""
    monkeypatch.setattr(driver, "_install_sigint", lambda flag: flag.update(flag=True))
    logdir = tmp_path / "run"
    code = train_cli.cli(["point-mass-ppo", "--num-timesteps", str(SHORT), "--log-every", "5120", "--eval-envs", "0",
                          "--logdir", str(logdir), "--no-progress", "--no-tensorboard"])
    assert code == train_cli.INTERRUPTED == 130
    assert "interrupted after 5,120 env steps" in capsys.readouterr().out
    assert Checkpointer(str(logdir / "checkpoints")).manager.all_steps() == [5120]


def test_run_files_are_replaced_whole(tmp_path):
    """config.json, eval.json and cross-*.json are written through a rename: a reader that opened the old file
    (another `run --parallel` worker) reads it whole, the next reader the whole new one, no temporary is left."""
    from agents.checkpoint import write_atomic

    path = tmp_path / "eval.json"
    path.write_text("old " * 1000)
    with open(path) as reader:
        write_atomic(str(path), "new")
        assert reader.read() == "old " * 1000  # written in place, this handle would see the truncated new text
    assert path.read_text() == "new"
    assert os.listdir(tmp_path) == ["eval.json"]


def test_a_failed_replace_leaves_no_temporary_file(tmp_path):
    from agents.checkpoint import write_atomic

    (tmp_path / "taken").mkdir()  # a folder where the file should go: the rename fails after the write
    with pytest.raises(OSError):
        write_atomic(str(tmp_path / "taken"), b"program")
    assert os.listdir(tmp_path) == ["taken"]

