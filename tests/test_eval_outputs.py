"""eval.py's output files: refused before any work when writing them would fail or destroy something (a run's or
an export's own files, an existing file without --force, a directory, a folder that cannot be written, a video
format whose writer is not installed, a missing package of the intervals), and written atomically; so are policy exports."""

import importlib.util
import json
import os
import sys

import numpy as np
import pytest

import eval as eval_cli
from agents import export

STANDSTILL = ["--env", "ur5e-reach", "--policy", "standstill", "--num-envs", "2", "--env.episode-length", "3",
              "--env.substeps", "2"]


@pytest.fixture
def run_dir(tmp_path):
    """A train.py logdir: config.json, metrics.csv, eval.json and a checkpoint step with its policy export."""
    run = tmp_path / "run"
    (run / "checkpoints" / "2048" / "policy").mkdir(parents=True)
    for name in ("config.json", "metrics.csv", "eval.json"):
        (run / name).write_text("the run's own\n")
    (run / "checkpoints" / "2048" / "policy" / "policy.json").write_text("{}")
    return run


@pytest.fixture
def export_dir(tmp_path):
    """A shipped policy export (results/checkpoints/<preset>/)."""
    export = tmp_path / "shipped"
    export.mkdir()
    (export / "policy.json").write_text("{}")
    (export / "policy.npz").write_bytes(b"")
    return export


def test_a_file_of_an_export_is_refused(export_dir):
    with pytest.raises(ValueError, match="is a file of the policy export"):
        eval_cli.check_output("--json", str(export_dir / "policy.json"), force=True)


def test_a_new_file_inside_an_export_is_refused(export_dir):
    with pytest.raises(ValueError, match="is a file of the policy export"):
        eval_cli.check_output("--json", str(export_dir / "report.json"), force=False)


def test_a_runs_training_log_is_refused_even_with_force(run_dir):
    with pytest.raises(ValueError, match="is a file of the run"):
        eval_cli.check_output("--csv", str(run_dir / "metrics.csv"), force=True)


def test_a_runs_eval_json_is_refused(run_dir):
    with pytest.raises(ValueError, match="is a file of the run"):
        eval_cli.check_output("--json", str(run_dir / "eval.json"), force=False)


def test_a_file_under_a_runs_checkpoints_is_refused(run_dir):
    with pytest.raises(ValueError, match="is a file of the run"):
        eval_cli.check_output("--json", str(run_dir / "checkpoints" / "2048" / "eval.json"), force=False)


def test_a_new_file_beside_a_runs_files_is_allowed(run_dir):
    assert eval_cli.check_output("--json", str(run_dir / "eval_front.json"), force=False) is None


def test_an_existing_file_needs_force(tmp_path):
    (tmp_path / "out.json").write_text("mine")
    with pytest.raises(ValueError, match="exists: allowed are a new path, or --force"):
        eval_cli.check_output("--json", str(tmp_path / "out.json"), force=False)


def test_force_allows_replacing_an_existing_file(tmp_path):
    (tmp_path / "out.json").write_text("mine")
    assert eval_cli.check_output("--json", str(tmp_path / "out.json"), force=True) is None


def test_a_directory_is_refused(tmp_path):
    with pytest.raises(ValueError, match="is a directory"):
        eval_cli.check_output("--csv", str(tmp_path), force=True)


def test_a_folder_that_is_a_file_is_refused(tmp_path):
    (tmp_path / "plain").write_text("")
    with pytest.raises(ValueError, match="cannot be written"):
        eval_cli.check_output("--json", str(tmp_path / "plain" / "out.json"), force=False)


def test_a_missing_folder_is_allowed_and_made(tmp_path):
    out = tmp_path / "new" / "deeper" / "out.json"
    eval_cli.main(STANDSTILL + ["--json", str(out)])
    assert json.loads(out.read_text())["env_name"] == "ur5e-reach"


def test_an_existing_output_is_refused_before_the_evaluation(tmp_path, monkeypatch):
    (tmp_path / "out.csv").write_text("mine")
    monkeypatch.setattr(eval_cli.evaluation, "run", lambda *a, **k: pytest.fail("evaluated before refusing"))
    with pytest.raises(ValueError, match="exists"):
        eval_cli.main(STANDSTILL + ["--csv", str(tmp_path / "out.csv")])
    assert (tmp_path / "out.csv").read_text() == "mine"


def test_force_replaces_the_file_whole(tmp_path):
    out = tmp_path / "out.csv"
    out.write_text("mine\n" * 100)
    eval_cli.main(STANDSTILL + ["--csv", str(out), "--force"])
    assert out.read_text().splitlines()[0].startswith("policy,env_name,env_config")


def test_no_temporary_file_is_left_beside_the_output(tmp_path):
    eval_cli.main(STANDSTILL + ["--json", str(tmp_path / "out.json")])
    assert sorted(p.name for p in tmp_path.iterdir()) == ["out.json"]


def test_an_mp4_without_its_writer_is_refused_before_the_evaluation(tmp_path, monkeypatch):
    real = importlib.util.find_spec
    monkeypatch.setattr(eval_cli.importlib.util, "find_spec", lambda name: None if name == "imageio_ffmpeg" else real(name))
    monkeypatch.setattr(eval_cli.evaluation, "run", lambda *a, **k: pytest.fail("evaluated before refusing"))
    with pytest.raises(ValueError, match="needs imageio_ffmpeg"):
        eval_cli.main(STANDSTILL + ["--video", str(tmp_path / "x.mp4")])


def test_a_missing_interval_package_is_refused_before_the_evaluation(monkeypatch):
    """The summary's confidence intervals over units (here 2 evaluation seeds) come after the evaluations; without
    rliable they would fail there and lose the evaluations' results."""
    monkeypatch.setitem(sys.modules, "rliable.library", None)  # its import fails, as in an install without it
    monkeypatch.setattr(eval_cli.evaluation, "run", lambda *a, **k: pytest.fail("evaluated before refusing"))
    with pytest.raises(ValueError, match=r"need rliable \(ModuleNotFoundError: import of rliable\.library halted"):
        eval_cli.main(STANDSTILL + ["--seeds", "2"])


def test_an_evaluation_of_one_unit_needs_no_interval_package(monkeypatch):
    """One unit has no interval: its evaluation runs without rliable."""
    monkeypatch.setitem(sys.modules, "rliable.library", None)  # its import fails, as in an install without it
    results = eval_cli.main(STANDSTILL)
    assert len(results[0].units) == 1


def test_an_evaluation_is_refused_before_it_runs_without_the_interval_packages(monkeypatch):
    """The same for every caller of agents.evaluation.run (the planner table, the experiments' cross-evaluations)."""
    monkeypatch.setitem(sys.modules, "arch.bootstrap", None)
    monkeypatch.setattr(eval_cli.evaluation, "_program", lambda *a, **k: pytest.fail("built the program before refusing"))
    config = eval_cli.envs.make_config("ur5e-reach", episode_length=3, substeps=2)
    with pytest.raises(ValueError, match=r"need .*arch \(ModuleNotFoundError: import of arch\.bootstrap halted"):
        eval_cli.evaluation.run(eval_cli.evaluation.baseline_policy("standstill"), "ur5e-reach", config, num_envs=2,
                                eval_seeds=[1, 2])


def _export_files(directory):
    return {name: (directory / name).read_bytes() for name in sorted(os.listdir(directory))}


def test_a_failed_export_write_keeps_the_old_export_whole(tmp_path, monkeypatch):
    """A write that fails half way (here np.savez raising, as on a full disk) leaves the previous policy.npz and
    policy.json byte for byte and no temporary file."""
    export._write(str(tmp_path), {"w": np.arange(3.0)}, {"format": 1})
    before = _export_files(tmp_path)

    def full_disk(file, **arrays):
        file.write(b"partial")
        raise OSError(28, "No space left on device")

    monkeypatch.setattr(export.np, "savez", full_disk)
    with pytest.raises(OSError, match="No space left"):
        export._write(str(tmp_path), {"w": np.arange(5.0)}, {"format": 2})
    assert _export_files(tmp_path) == before


def test_an_export_write_replaces_both_files(tmp_path):
    export._write(str(tmp_path), {"w": np.arange(3.0)}, {"format": 1})
    export._write(str(tmp_path), {"w": np.arange(5.0)}, {"format": 2})
    assert json.loads((tmp_path / "policy.json").read_text()) == {"format": 2}
    with np.load(tmp_path / "policy.npz") as data:
        np.testing.assert_array_equal(data["w"], np.arange(5.0))
    assert sorted(os.listdir(tmp_path)) == ["policy.json", "policy.npz"]


def test_the_progress_line_keeps_each_trained_seeds_rate():
    units = [{"metrics": {"target_reached": r, "self_collision": 0.02}} for r in (0.75, 0.79)]
    line = eval_cli.evaluation.seed_line(0, 1, 7, units, 3.0)
    assert "77.0 % reached" in line  # the mean of 75.0 and 79.0
    assert "reached % each: 75.0, 79.0" in line


def test_the_progress_line_of_one_trained_seed_names_no_other():
    line = eval_cli.evaluation.seed_line(0, 1, 7, [{"metrics": {"target_reached": 0.75}}], 3.0)
    assert "trained seeds" not in line


def test_a_result_summarises_once(monkeypatch):
    """Its summary (intervals over 2 evaluation seeds: bootstrap resampling) is computed once for the table and JSON."""
    calls = []
    original = eval_cli.evaluation.summarize
    monkeypatch.setattr(eval_cli.evaluation, "summarize", lambda per_env: calls.append(1) or original(per_env))
    result = eval_cli.main(STANDSTILL + ["--seeds", "2"])[0]
    result.to_json()
    result.summary()
    assert len(calls) == 1
