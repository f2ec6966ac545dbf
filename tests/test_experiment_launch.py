"""tools/experiment_launch.py through submitit: the point-mass demo launched on submitit's local executor trains in
one job; launched at the same time on a real single-node Slurm with a one-minute time limit, it is stopped, requeued
and resumed, and ends with the same final evaluation and training log as the unbroken run of the same seed; a
failing part reports its error in `list`."""

import csv
import json
import os
import subprocess
import sys

import pytest

from agents.config import config_json
from tests.slurm_cluster import ensure_slurm
from tools import experiment_launch as launch
from tools import experiment_spec as spec
from tools import experiment_state as state
from tools import experiments as ex

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))  # the checkout

DEMO = "point-mass-demo"
PART = os.path.join(DEMO, "ppo", "seeds-0-0")
TIMING = ("steps_per_second", "wall_seconds")
"""metrics.csv columns that measure the machine, not the run."""


def _launch(runs: str, *options: str) -> subprocess.Popen:
    """Starts `python -m tools.experiments launch point-mass-demo` as a user types it, with its runs and results in
    `runs` (its output in `runs/launch.log`)."""
    os.makedirs(runs, exist_ok=True)
    argv = [sys.executable, "-m", "tools.experiments", "launch", DEMO, "--runs-dir", os.path.join(runs, "runs"),
            "--out", os.path.join(runs, "out"), "--compilation-cache", os.path.join(runs, "jax_cache"), *options]
    with open(os.path.join(runs, "launch.log"), "w") as log:
        return subprocess.Popen(argv, cwd=ROOT, stdout=log, stderr=subprocess.STDOUT, text=True)


def _ended(process: subprocess.Popen, runs: str) -> str:
    """Waits for a launch; returns its output, asserting it exited 0."""
    code = process.wait(timeout=900)
    with open(os.path.join(runs, "launch.log")) as f:
        text = f.read()
    assert code == 0, text[-3000:]
    return text


def _evaluation(runs: str) -> dict:
    with open(os.path.join(runs, "runs", PART, "eval.json")) as f:
        return json.load(f)


def _log(runs: str) -> list[dict]:
    """metrics.csv's rows without the timing columns."""
    with open(os.path.join(runs, "runs", PART, "metrics.csv"), newline="") as f:
        return [{k: v for k, v in row.items() if k not in TIMING} for row in csv.DictReader(f)]


@pytest.fixture(scope="module")
def launched(tmp_path_factory) -> dict:
    """The demo launched twice side by side: on submitit's local executor without a time limit to meet (one job, one
    attempt: the unbroken reference), and, where a Slurm cluster answers, on Slurm with a 1-minute limit (warned
    25-55 s after each start, as Slurm checks limits every 30 s). {"local": runs folder, "slurm": runs folder or
    the reason there is none}."""
    root = tmp_path_factory.mktemp("launched")
    ok, why = ensure_slurm()
    runs = {"local": str(root / "local"), "slurm": str(root / "slurm") if ok else f"no Slurm cluster here: {why}"}
    started = {"local": _launch(runs["local"], "--executor", "local", "--gpus-per-part", "0")}
    if ok:
        started["slurm"] = _launch(runs["slurm"], "--executor", "slurm", "--time", "1", "--signal-delay", "5",
                                   "--max-requeues", "20", "--gpus-per-part", "0", "--wait")
    for name, process in started.items():
        _ended(process, runs[name])
    return runs


def test_launch_config_is_validated_where_it_is_made():
    with pytest.raises(ValueError, match=r"executor='pbs' is unknown: allowed are slurm, local"):
        launch.LaunchConfig(executor="pbs")
    with pytest.raises(ValueError, match=r"gpus_per_part=-1 is impossible: allowed is a whole number >= 0"):
        launch.LaunchConfig(gpus_per_part=-1)
    with pytest.raises(ValueError, match=r"slurm_args entry \('--qos', 'high'\) is invalid"):
        launch.LaunchConfig(slurm_args=(("--qos", "high"),))
    assert launch.LaunchConfig(time_min=1).warning_s == 15  # a quarter of the limit
    assert launch.LaunchConfig(time_min=240).warning_s == 120  # at most two minutes
    assert launch.LaunchConfig(time_min=1, signal_delay_s=40).warning_s == 40


def test_local_slots_group_the_visible_gpus(monkeypatch):
    monkeypatch.setenv("CUDA_VISIBLE_DEVICES", "2,3,5")
    assert launch.gpu_slots(1) == [[2], [3], [5]]
    assert launch.gpu_slots(2) == [[2, 3]]  # GPU 5 alone is too few for a part
    assert launch.gpu_slots(0) == [[]]
    monkeypatch.setenv("CUDA_VISIBLE_DEVICES", "")
    assert launch.gpu_slots(1) == [[]]  # no GPU: one part at a time on the CPU


def test_the_local_executor_trains_a_part_in_one_job_and_records_it(launched):
    unbroken = launched["local"]
    job = json.load(open(os.path.join(unbroken, "runs", DEMO, "ppo", ".seeds-0-0.job.json")))
    assert job["executor"] == "local"
    assert job["status"] == "done"
    assert job["attempts"] == 1
    assert _evaluation(unbroken)["env_steps"] >= spec.EXPERIMENTS[DEMO].runs[0].budget()
    recorded = os.path.join(unbroken, "out", DEMO, "runs", "ppo", "seeds-0-0", "eval.json")
    assert json.load(open(recorded))["per_seed"] == _evaluation(unbroken)["per_seed"]
    listed = ex.listing(state.select([DEMO]), os.path.join(unbroken, "runs"), os.path.join(unbroken, "out"))
    assert "  1 done; table not built" in listed


def test_slurm_requeues_a_part_past_its_limit_and_ends_as_an_unbroken_run(launched):
    """A real Slurm: the job with a 1-minute limit is warned, saves a checkpoint, is requeued and resumes until the
    part is done; its evaluation and training log (step for step) equal the unbroken run's."""
    runs, unbroken = launched["slurm"], launched["local"]
    if runs.startswith("no Slurm"):
        pytest.skip(runs)
    job = json.load(open(os.path.join(runs, "runs", DEMO, "ppo", ".seeds-0-0.job.json")))
    assert job["executor"] == "slurm"
    assert job["status"] == "done", open(job["log"]).read()[-3000:]
    assert job["attempts"] >= 2  # requeued at least once
    assert _evaluation(runs)["per_seed"] == _evaluation(unbroken)["per_seed"]
    assert _log(runs) == _log(unbroken)


def test_a_failing_part_reports_its_error_in_list(tmp_path, monkeypatch):
    """A part whose folder holds another run's config fails in its job; `list` names the job, the error and the
    log."""
    runs = str(tmp_path)
    logdir = os.path.join(runs, "runs", PART)
    os.makedirs(logdir)
    run = spec.EXPERIMENTS[DEMO].runs[0]
    other = spec.apply_overrides(run.config(logdir), {"env.dt": 0.2})
    with open(os.path.join(logdir, "config.json"), "w") as f:
        json.dump(config_json(other), f)
    # A changed part is not launched: the launch says why and exits 1 (the run is not done).
    assert _launch(runs, "--executor", "local").wait(timeout=300) == 1
    text = open(os.path.join(runs, "launch.log")).read()
    assert "skipped: seeds-0-0:" in text
    assert "dt" in text
    assert "not finished: point-mass-demo/ppo" in text
    # Launched by name as a job, it fails there and the job file keeps the error.
    job = launch.make_executor(launch.LaunchConfig(executor="local", time_min=5), os.path.join(runs, "jobs")).submit(
        launch.PartJob(f"{DEMO}/ppo", "seeds-0-0", os.path.join(runs, "runs"), os.path.join(runs, "out"), "off"))
    with pytest.raises(Exception, match="move that part away to retrain it"):
        job.result()
    text = ex.listing(state.select([DEMO]), os.path.join(runs, "runs"), os.path.join(runs, "out"))
    assert f"seeds-0-0: failed in job {job.job_id}: ValueError: " in text
    assert "move that part away to retrain it" in text


class _EndedJob:
    """A job whose result file is missing (it ended without a word), as `_after_job` sees it."""

    def __init__(self, folder, job_id="7"):
        self.job_id = job_id
        self.paths = type("Paths", (), {"result_pickle": folder / "missing_result.pkl"})()


def test_a_job_killed_by_the_cluster_is_submitted_again_until_the_requeues_run_out(tmp_path, monkeypatch):
    logdir = str(tmp_path / "run" / "seeds-0-0")
    launch.note_job(logdir, status="running", attempts=1, error=None)
    monkeypatch.setattr(launch, "slurm_state", lambda job_id: "TIMEOUT")
    said = []
    config = launch.LaunchConfig(executor="slurm", max_requeues=2)
    assert launch._after_job(_EndedJob(tmp_path), "e/r", "seeds-0-0", logdir, config, 1, said.append)
    assert "ended by the cluster (TIMEOUT)" in said[-1]
    assert launch.read_job(logdir)["status"] == "running"  # left for the next job to take over
    assert not launch._after_job(_EndedJob(tmp_path), "e/r", "seeds-0-0", logdir, config, 2, said.append)
    assert launch.read_job(logdir)["status"] == "killed"
    assert launch.read_job(logdir)["error"] == "job 7 ended without a result (TIMEOUT)"


def test_a_job_its_user_cancelled_is_noted_as_killed_not_submitted_again(tmp_path):
    """A real Slurm job cancelled by `scancel` ends CANCELLED: reported, not resubmitted."""
    ok, why = ensure_slurm()
    if not ok:
        pytest.skip(why)
    job_id = subprocess.run(["sbatch", "--parsable", "-o", "/dev/null", "--wrap", "sleep 120"], capture_output=True,
                            text=True, check=True).stdout.strip().split(";")[0]
    assert launch.slurm_listed(job_id) is True  # pending or running
    subprocess.run(["scancel", job_id], check=True)
    for _ in range(60):
        if launch.slurm_state(job_id) == "CANCELLED" and launch.slurm_listed(job_id) is not True:
            break
        subprocess.run(["sleep", "1"])
    assert launch.slurm_state(job_id) == "CANCELLED"
    assert launch.slurm_listed(job_id) is not True  # gone from squeue (or unknown to it)
    logdir = str(tmp_path / "run" / "seeds-0-0")
    launch.note_job(logdir, status="running", attempts=1, error=None, log="slurm.err")
    said = []
    config = launch.LaunchConfig(executor="slurm", max_requeues=5)
    assert not launch._after_job(_EndedJob(tmp_path, job_id), "e/r", "seeds-0-0", logdir, config, 0, said.append)
    assert said[-1] == (f"[e/r seeds-0-0] job {job_id} ended: killed (job {job_id} ended without a result "
                        "(CANCELLED); log slurm.err)")


class _ResultJob(_EndedJob):
    """A job whose result file is written (a return, or the exception of a stopped attempt)."""

    def __init__(self, folder, job_id="7"):
        super().__init__(folder, job_id)
        self.paths.result_pickle = folder / "result.pkl"
        self.paths.result_pickle.write_bytes(b"")


def test_a_slurm_job_still_listed_has_not_ended_though_an_attempt_left_a_result(tmp_path, monkeypatch):
    """A job that requeued itself keeps its id while an earlier attempt's result file lies in its folder."""
    monkeypatch.setattr(launch, "slurm_listed", lambda job_id: True)
    assert not launch.job_ended(_ResultJob(tmp_path), "slurm")
    monkeypatch.setattr(launch, "slurm_listed", lambda job_id: False)
    assert launch.job_ended(_ResultJob(tmp_path), "slurm")
    assert launch.job_ended(_EndedJob(tmp_path), "slurm")  # gone without a result: killed


def test_without_squeue_a_slurm_job_has_ended_once_its_result_is_written(tmp_path, monkeypatch):
    monkeypatch.setattr(launch, "slurm_listed", lambda job_id: None)
    assert launch.job_ended(_ResultJob(tmp_path), "slurm")
    assert not launch.job_ended(_EndedJob(tmp_path), "slurm")


def test_a_job_gone_after_stopping_to_requeue_is_submitted_again_until_the_requeues_run_out(tmp_path):
    logdir = str(tmp_path / "run" / "seeds-0-0")
    launch.note_job(logdir, status="interrupted", attempts=1, error=None)
    said = []
    config = launch.LaunchConfig(executor="slurm", max_requeues=2)
    assert launch._after_job(_ResultJob(tmp_path), "e/r", "seeds-0-0", logdir, config, 1, said.append)
    assert "stopped to requeue itself but is gone" in said[-1]
    assert not launch._after_job(_ResultJob(tmp_path), "e/r", "seeds-0-0", logdir, config, 2, said.append)
    assert said[-1] == "[e/r seeds-0-0] job 7 ended: interrupted"


def test_a_finished_job_keeps_the_status_its_code_wrote(tmp_path):
    logdir = str(tmp_path / "run" / "seeds-0-0")
    launch.note_job(logdir, status="done", attempts=2, error=None)
    said = []
    assert not launch._after_job(_EndedJob(tmp_path), "e/r", "seeds-0-0", logdir,
                                 launch.LaunchConfig(executor="slurm"), 0, said.append)
    assert said == ["[e/r seeds-0-0] job 7 ended: done"]
