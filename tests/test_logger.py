"""The training log (`agents.logger.Logger`): the status line's ETA and episode metrics of chunks in which no episode
ended; a resumed run's rows under its metrics.csv's header."""

import csv
import warnings

import numpy as np

from agents import logger


def _progress_line(tmp_path, capsys, compiled, metrics=None):
    log = logger.Logger(str(tmp_path), seed=0, seeds=1, label="x", tensorboard=False)
    log.progress(1_000, 3_000, 500.0, metrics or {}, compiled=compiled)
    return capsys.readouterr().out


def test_progress_leaves_out_an_episode_metric_of_a_chunk_in_which_no_episode_ended(tmp_path, capsys):
    with warnings.catch_warnings():
        warnings.simplefilter("error")  # no "Mean of empty slice"
        line = _progress_line(tmp_path, capsys, False, {"episode/return": np.array([np.nan, np.nan]),
                                                        "episode/length": np.array([np.nan, 4.0])})
    assert "return" not in line.split("ETA")[1]
    assert "length 4" in line


def test_progress_gives_the_eta_of_the_remaining_steps(tmp_path, capsys):
    assert "ETA 0:00:04" in _progress_line(tmp_path, capsys, compiled=False)  # 2,000 steps at 500 a second


def test_progress_after_a_chunk_that_compiled_gives_no_eta(tmp_path, capsys):
    line = _progress_line(tmp_path, capsys, compiled=True)
    assert "incl. compiling" in line
    assert "ETA after the next chunk" in line


def test_a_resumed_run_logs_under_its_files_header(tmp_path, capsys):
    """A run resumed by code that logs other metrics appends rows under the header its metrics.csv began with
    (before: rows of another width, misaligned under it); a fresh file gets this code's columns."""
    path = tmp_path / "metrics.csv"
    path.write_text("env_steps,seed,steps_per_second,loss/a\n10,0,5.0,1.5\n")
    log = logger.Logger(str(tmp_path), seed=0, seeds=2, label="x", tensorboard=False, progress=False)
    log.log(20, {"loss/a": np.array([2.0, 3.0]), "loss/b": np.array([7.0, 8.0])},
            {"steps_per_second": 9.0, "wall_seconds": 1.0})
    with open(path, newline="") as f:
        assert list(csv.reader(f)) == [["env_steps", "seed", "steps_per_second", "loss/a"], ["10", "0", "5.0", "1.5"],
                                       ["20", "0", "9.0", "2.0"], ["20", "1", "9.0", "3.0"]]
    assert "has no column for wall_seconds, loss/b" in capsys.readouterr().err
    fresh = tmp_path / "fresh"
    fresh.mkdir()
    logger.Logger(str(fresh), seed=3, seeds=1, label="x", tensorboard=False, progress=False).log(
        5, {"loss/b": np.array([1.0])}, {"wall_seconds": 2.0})
    assert (fresh / "metrics.csv").read_text().splitlines() == ["env_steps,seed,wall_seconds,loss/b", "5,3,2.0,1.0"]
