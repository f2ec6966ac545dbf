"""Training an experiment's parts: in this process (`run_parts`), or as jobs handed to a scheduler through submitit
(`launch`): Slurm, or submitit's local executor for one machine (one part per GPU at a time).

A part's job (`PartJob`) trains its seeds, resuming from the part's newest checkpoint, evaluates its cross settings
and records its files in the results. A job warned of its time limit or of a preemption (SIGUSR2) saves a
checkpoint after the current chunk of updates, is requeued and resumes there, so a part ends with what an unbroken
run of the same seeds gives. Each part keeps a job file beside its folder (`.seeds-0-4.job.json`: job id, attempts,
log, error) that `list` reads.
"""

from __future__ import annotations

import contextlib
import dataclasses
import datetime
import fcntl
import json
import os
import re
import signal
import socket
import subprocess
import time
import traceback

import submitit

from agents import driver, intervals, provenance, xla_flags
from agents.checkpoint import write_atomic
from tools.experiment_state import (
    cross_evaluate, folder_crosses, parse_part, part_state, pending_parts, planners, run_state, select,
)
from tools.experiment_tables import record_parts

EXECUTORS = ("slurm", "local")
"""`launch`'s executors: a Slurm cluster, or this machine's GPUs (its CPU where it has none)."""
CHECKPOINTS_PER_PART = 20
"""A part saves a checkpoint every 1/20 of its budget, so a job killed before it could save on its warning (a chunk
longer than the warning, a lost node) loses at most that much."""
KILLED_STATES = ("TIMEOUT", "PREEMPTED", "NODE_FAIL", "BOOT_FAIL")
"""Slurm job states of a job ended by the cluster, not by its code or its user: a waiting `launch` submits such a
part again (it resumes from its newest checkpoint)."""


@dataclasses.dataclass(frozen=True)
class LaunchConfig:
    """How `launch` hands parts to the scheduler (the command line's options)."""

    executor: str = "slurm"
    """slurm: one job per part on the cluster; local: this machine, one part per GPU at a time."""
    time_min: int = 240
    """Each job's time limit in minutes; a part that needs longer is requeued and resumes from its checkpoint."""
    partition: str = ""
    """Slurm partition ("": the cluster's default)."""
    gpus_per_part: int = 1
    """GPUs each job asks for (the training loop uses every GPU it sees); 0 trains on the CPU."""
    cpus_per_part: int = 0
    """CPU cores each Slurm job asks for (0: the cluster's default)."""
    max_requeues: int = 10
    """How often a job may be requeued after reaching its time limit before it gives up (preemptions not counted)."""
    signal_delay_s: int = 0
    """Seconds before the time limit that the job is warned (SIGUSR2) to checkpoint; 0: a quarter of the limit, at
    most 120. Slurm checks its limits every 30 s, so the warning comes up to 30 s earlier than this."""
    slurm_args: tuple = ()
    """Further sbatch options as (key, value) pairs, e.g. (("account", "rl"), ("qos", "high"))."""
    wait: bool = False
    """Slurm: block until every job has ended (the local executor always waits)."""
    folder: str = ""
    """Where submitit keeps the jobs' scripts and logs ("": `<runs-dir>/jobs`)."""

    def __post_init__(self):
        if self.executor not in EXECUTORS:
            raise ValueError(f"executor={self.executor!r} is unknown: allowed are {', '.join(EXECUTORS)}.")
        for name, low in (("time_min", 1), ("gpus_per_part", 0), ("cpus_per_part", 0), ("max_requeues", 0),
                          ("signal_delay_s", 0)):
            value = getattr(self, name)
            if not isinstance(value, int) or isinstance(value, bool) or value < low:
                raise ValueError(f"{name}={value!r} is impossible: allowed is a whole number >= {low}.")
        if self.signal_delay_s >= 60 * self.time_min:
            raise ValueError(f"signal_delay_s={self.signal_delay_s} is impossible with time_min={self.time_min}: "
                             f"allowed is less than the limit, {60 * self.time_min} s.")
        for pair in self.slurm_args:
            if len(pair) != 2 or not str(pair[0]) or str(pair[0]).startswith("-"):
                raise ValueError(f"slurm_args entry {pair!r} is invalid: allowed is (option name without dashes, value).")

    @property
    def warning_s(self) -> int:
        return self.signal_delay_s or min(120, 15 * self.time_min)


# ------------------------------------------------------------------------------------------------
# A part's lock and job file, beside its folder (a fresh start may clear the folder itself).


def lock_path(logdir: str) -> str:
    """The lock file of part folder `logdir`: `<run folder>/.<part>.lock`."""
    return os.path.join(os.path.dirname(logdir), f".{os.path.basename(logdir)}.lock")


@contextlib.contextmanager
def part_lock(logdir: str):
    """Holds an exclusive `flock` on the part's lock file while the part trains, so that two processes sharing a
    runs folder never train one part at once (the kernel drops it when its process ends, even killed). Yields None
    while held, or why the part is taken (the holder's pid and host)."""
    path = lock_path(logdir)
    os.makedirs(os.path.dirname(path), exist_ok=True)
    with open(path, "a+") as f:
        try:
            fcntl.flock(f, fcntl.LOCK_EX | fcntl.LOCK_NB)
        except BlockingIOError:
            f.seek(0)
            yield f"another process ({f.read().strip() or 'pid unknown'}) holds its lock {path}"
            return
        try:
            f.seek(0)
            f.truncate()
            f.write(f"pid {os.getpid()} on {socket.gethostname()}")
            f.flush()
            yield None
        finally:
            fcntl.flock(f, fcntl.LOCK_UN)


def job_path(logdir: str) -> str:
    """The job file of part folder `logdir`: `<run folder>/.<part>.job.json`."""
    return os.path.join(os.path.dirname(logdir), f".{os.path.basename(logdir)}.job.json")


def read_job(logdir: str) -> dict | None:
    """The part's job file (None without one, or unreadable)."""
    try:
        with open(job_path(logdir)) as f:
            return json.load(f)
    except (OSError, ValueError):
        return None


def note_job(logdir: str, **fields) -> dict:
    """Updates the part's job file with `fields` (written atomically); returns the new content."""
    job = {**(read_job(logdir) or {}), **fields}
    os.makedirs(os.path.dirname(job_path(logdir)), exist_ok=True)
    write_atomic(job_path(logdir), json.dumps(job, indent=2))
    return job


def now() -> str:
    return datetime.datetime.now().isoformat(timespec="seconds")


def describe_job(logdir: str) -> str:
    """The listing's note on a part's job: "failed in job 12: ValueError: ... (log ...)", "job 12 (slurm, attempt
    2)", or ""."""
    job = read_job(logdir)
    if not job:
        return ""
    if job.get("error"):
        return f"failed in job {job.get('job_id')}: {job['error']}" + (f" (log {job['log']})" if job.get("log") else "")
    if job.get("status") == "done":
        return ""
    return f"job {job.get('job_id')} ({job.get('executor')}, attempt {job.get('attempts', 0)})"


# ------------------------------------------------------------------------------------------------
# Training one part.


def find_run(key: str):
    """(experiment, run) of "experiment/run"; ValueError naming an unknown one."""
    (experiment, runs), = select([key])
    if len(runs) != 1:
        raise ValueError(f"run {key!r} is not one run: allowed is experiment/run.")
    return experiment, runs[0]


def train_part(key: str, part: str, runs_dir: str, out: str, log=print) -> str:
    """Trains part `part` ("seeds-<first>-<last>") of run `key` to its budget (resuming from its newest checkpoint),
    then evaluates its cross settings and records its files in `out`. Returns "done", "interrupted" (a stop signal:
    a checkpoint was saved), or "taken" (another process holds the part). ValueError for a part whose stored
    config differs from the registry's run."""
    intervals.check_installed()  # the cross-evaluations' intervals come after the training
    experiment, run = find_run(key)
    span = parse_part(part)
    if span is None:
        raise ValueError(f"part={part!r} is not a part name: allowed is seeds-<first>-<last>.")
    folder = run_state(experiment, run, runs_dir, out).folder
    logdir = os.path.join(folder, part)
    with part_lock(logdir) as taken:
        if taken is not None:
            log(f"[{key} {part}] left alone: {taken}")
            return "taken"
        state = part_state(run, logdir, *span)
        if state.status == "changed":
            raise ValueError(f"{key} {part}: {state.reason}; move that part away to retrain it")
        if state.status != "done":
            resume = state.steps > 0
            # A part stopped before its first checkpoint left config.json and logs only: start it afresh.
            fresh_over = not resume and os.path.isdir(logdir) and bool(os.listdir(logdir))
            log(f"[{key} {part}] {'resuming at ' + format(state.steps, ',') if resume else 'starting'}; "
                f"to {state.budget:,} steps x {state.count} seeds")
            config = run.config(logdir, first_seed=span[0], seeds=span[1], resume=resume, overwrite=fresh_over,
                                stop_after_steps=0, stop_after_seconds=0.0,
                                checkpoint_every=max(1, state.budget // CHECKPOINTS_PER_PART))
            result = driver.train(config)
            log(f"[{key} {part}] {result.status} at {result.env_steps:,} steps")
            if result.status != "done":
                return result.status
        st = run_state(experiment, run, runs_dir, out)
        for run_x, _, done_part, cross in folder_crosses(experiment, st, runs_dir, out):
            if done_part.name == part:
                log(f"[{key} {part}] cross-evaluation {cross.name!r}: {cross.setting}")
                cross_evaluate(run_x, done_part, cross)
        for path in record_parts(run_state(experiment, run, runs_dir, out), out, only=part):
            log(f"recorded {path}")
    return "done"


@dataclasses.dataclass
class PartJob(submitit.helpers.Checkpointable):
    """One part as a submitit job. Requeued by submitit's `checkpoint` (the same job again) after a stop signal;
    the part's checkpoint on disk is its state."""

    key: str
    part: str
    runs_dir: str
    out: str
    compilation_cache: str | None = None

    def __call__(self) -> str:
        logdir = part_folder(self.key, self.part, self.runs_dir, self.out)
        job = read_job(logdir) or {}
        note_job(logdir, job_id=submitit.JobEnvironment().job_id, attempts=job.get("attempts", 0) + 1,
                 started=now(), status="running", error=None)
        # submitit's handler for the stop signal: it calls `checkpoint` and requeues the job. While training, the
        # driver takes the signal instead, saves a checkpoint and returns; the requeue follows here.
        requeue = signal.getsignal(signal.SIGUSR2)
        try:
            xla_flags.compilation_cache(self.compilation_cache)
            status = train_part(self.key, self.part, self.runs_dir, self.out)
        except Exception as error:
            last = traceback.format_exception_only(error)[-1].strip()
            note_job(logdir, status="failed", error=last.splitlines()[0], ended=now())
            raise
        note_job(logdir, status=status, ended=now())
        if status == "interrupted" and callable(requeue):
            requeue(signal.SIGUSR2, None)  # exits the process once requeued
        return status


# ------------------------------------------------------------------------------------------------
# Choosing and launching parts.


def parts_to_train(selection, runs_dir: str, out: str, max_seeds: int | None = None, log=print) -> list[tuple[str, str]]:
    """(run key, part name) for each part a job can take on its own: done parts whose cross-evaluations are still to
    make where their checkpoints are, then the parts still to train (at most `max_seeds` seeds each). Runs sharing a
    folder are planned once (`planners`); changed runs are reported and left out."""
    for exp, runs in selection:
        for r in runs:
            st = run_state(exp, r, runs_dir, out)
            if st.status == "changed":
                log(f"[{st.key}] skipped: {st.reason}; move that part away to retrain it")
    plans = planners(selection, runs_dir, out)
    crosses = [(st.key, part.name) for exp, st in plans for _, _, part, _ in folder_crosses(exp, st, runs_dir, out)]
    training = [(st.key, part.name) for _, st in plans if st.status != "done" for part in pending_parts(st, max_seeds)]
    return list(dict.fromkeys(crosses + training))


def run_parts(selection, runs_dir: str, out: str, max_seeds: int | None = None, log=print) -> bool:
    """Trains the selected runs' parts one after another in this process; True when every selected run is done,
    False after a stop signal (a checkpoint is saved: run again to continue)."""
    for key, part in parts_to_train(selection, runs_dir, out, max_seeds, log):
        if train_part(key, part, runs_dir, out, log) == "interrupted":
            return False
    return all(run_state(exp, r, runs_dir, out).status == "done" for exp, runs in selection for r in runs)


def local_gpus() -> list[int]:
    """The GPUs of this machine that jobs may use: CUDA_VISIBLE_DEVICES's entries where it is set, else those
    `nvidia-smi -L` lists (read without starting jax, which would take the first GPU's memory)."""
    visible = os.environ.get("CUDA_VISIBLE_DEVICES")
    if visible is not None:
        return [int(d) for d in visible.split(",") if d.strip().isdigit()]
    try:
        listed = subprocess.run(["nvidia-smi", "-L"], capture_output=True, text=True, timeout=30).stdout
    except (OSError, subprocess.SubprocessError):
        return []
    return list(range(sum(line.startswith("GPU ") for line in listed.splitlines())))


def gpu_slots(gpus_per_part: int) -> list[list[int]]:
    """The local executor's job slots: this machine's GPUs in groups of `gpus_per_part` (a leftover too small for a
    part stays idle); one slot without GPUs where there are none or `gpus_per_part` is 0."""
    if not gpus_per_part:
        return [[]]
    gpus = local_gpus()
    slots = [gpus[i:i + gpus_per_part] for i in range(0, len(gpus), gpus_per_part)]
    return [s for s in slots if len(s) == gpus_per_part] or [[]]


def job_ended(job, executor: str) -> bool:
    """Whether a submitted job has ended. Local: its result file is written (a return or an exception) or its process
    is gone. Slurm: `squeue` no longer lists it, whether or not it wrote a result (clusters without accounting have
    no `sacct`, which submitit's own wait needs for a job killed without one). A listed job has not ended even with a
    result file: a job that requeued itself keeps its id, and its stopped attempt may have left one (the requeue's
    own stop signal can end `scontrol requeue` and so raise in the job, after Slurm took the requeue)."""
    if executor == "local":
        return job.paths.result_pickle.exists() or job.done()
    listed = slurm_listed(job.job_id)
    return job.paths.result_pickle.exists() if listed is None else not listed


def slurm_listed(job_id: str) -> bool | None:
    """Whether `squeue` lists the job (pending, running, requeued or completing); None where it cannot say."""
    try:
        listed = subprocess.run(["squeue", "-h", "-j", str(job_id), "-o", "%i"], capture_output=True, text=True,
                                timeout=60)
    except (OSError, subprocess.SubprocessError):
        return None
    return bool(listed.stdout.strip()) if listed.returncode == 0 else None


def slurm_state(job_id: str) -> str:
    """The Slurm state of a job ("TIMEOUT", "COMPLETED", ...): `scontrol show job` (which knows a finished job for
    the cluster's MinJobAge), else `sacct`; "" where neither knows it."""
    for argv in (["scontrol", "show", "job", "-o", str(job_id)], ["sacct", "-n", "-X", "-P", "-o", "State", "-j",
                                                                    str(job_id)]):
        try:
            text = subprocess.run(argv, capture_output=True, text=True, timeout=60).stdout
        except (OSError, subprocess.SubprocessError):
            continue
        found = re.search(r"JobState=(\w+)", text) if argv[0] == "scontrol" else re.match(r"\s*([A-Z_]+)", text)
        if found:
            return found.group(1)
    return ""


def _after_job(job, key: str, part: str, logdir: str, config: "LaunchConfig", resubmits: int, log) -> bool:
    """Reports how a part's job ended (its job file's status). A job that ended without a word (its file still says
    running: killed) is noted as killed; on Slurm, one killed by the cluster (`KILLED_STATES`), or one that stopped
    to requeue itself and is gone (its requeue failed), is to be submitted again while `config.max_requeues` allows.
    Returns whether to submit it again."""
    note = read_job(logdir) or {}
    if note.get("status") in ("submitted", "running") and not job.paths.result_pickle.exists():
        state = slurm_state(job.job_id) if config.executor == "slurm" else ""
        if state in KILLED_STATES and resubmits < config.max_requeues:
            log(f"[{key} {part}] job {job.job_id} ended by the cluster ({state}) before it could requeue itself; "
                "submitting the part again (it resumes from its newest checkpoint)")
            return True
        note = note_job(logdir, status="killed", ended=now(),
                        error=f"job {job.job_id} ended without a result ({state or 'its process died'})")
    elif note.get("status") == "interrupted" and config.executor == "slurm" and resubmits < config.max_requeues:
        log(f"[{key} {part}] job {job.job_id} stopped to requeue itself but is gone; submitting the part again (it "
            "resumes from its newest checkpoint)")
        return True
    log(f"[{key} {part}] job {job.job_id} ended: {note.get('status', 'unknown')}"
        + (f" ({note['error']}; log {note.get('log')})" if note.get("error") else ""))
    return False


def make_executor(config: LaunchConfig, folder: str):
    """The submitit executor for `config` (Slurm's parameters: time, partition, GPUs, the stop warning)."""
    if config.executor == "local":
        executor = submitit.LocalExecutor(folder=folder, max_num_timeout=config.max_requeues)
        executor.update_parameters(timeout_min=config.time_min, signal_delay_s=config.warning_s)
        return executor
    executor = submitit.SlurmExecutor(folder=folder, max_num_timeout=config.max_requeues)
    params = dict(time=config.time_min, signal_delay_s=config.warning_s, gpus_per_node=config.gpus_per_part or None,
                  ntasks_per_node=1, additional_parameters=dict(config.slurm_args))
    if config.partition:
        params["partition"] = config.partition
    if config.cpus_per_part:
        params["cpus_per_task"] = config.cpus_per_part
    executor.update_parameters(**{k: v for k, v in params.items() if v is not None})
    return executor


def launch(selection, config: LaunchConfig, runs_dir: str, out: str, max_seeds: int | None = None,
           compilation_cache: str | None = None, log=print) -> list:
    """Submits one job per part to train (`parts_to_train`); returns the jobs. Slurm: every part at once (waiting
    for them with `config.wait`); local: one part per GPU (one at a time without a GPU), the next part as a GPU
    frees, returning when all have ended. Waiting, it logs how each part's job ended (its job file's status)."""
    runs_dir, out = os.path.abspath(runs_dir), os.path.abspath(out)
    folder = config.folder or os.path.join(runs_dir, "jobs")
    items = parts_to_train(selection, runs_dir, out, max_seeds, log)
    if not items:
        log("nothing to train: every selected run is done")
        return []
    executor = make_executor(config, os.path.join(folder, "%j"))
    # The jobs' results name the command that launched them (a job itself runs submitit's bootstrap).
    os.environ.setdefault(provenance.COMMAND_VARIABLE, provenance.command())
    slots = gpu_slots(config.gpus_per_part) if config.executor == "local" else []
    jobs, running = [], {}

    folders = {item: part_folder(*item, runs_dir, out) for item in items}

    def submit(key, part, slot=None):
        logdir = folders[key, part]
        note_job(logdir, executor=config.executor, submitted=now(), status="submitted", error=None)
        job = executor.submit(PartJob(key, part, runs_dir, out, compilation_cache))
        note_job(logdir, job_id=job.job_id, log=str(job.paths.stderr))
        log(f"[{key} {part}] job {job.job_id}" + (f" on GPU {','.join(map(str, slots[slot]))}"
                                                  if slot is not None and slots[slot] else ""))
        return job

    for key, part in items:
        note_job(folders[key, part], attempts=0)
        if config.executor == "local":
            while len(running) >= len(slots):  # wait for a free GPU
                for i, job in list(running.items()):
                    if job.done():
                        del running[i]
                time.sleep(1)
            slot = min(set(range(len(slots))) - set(running))
            executor.update_parameters(visible_gpus=slots[slot], gpus_per_node=len(slots[slot]))
            running[slot] = submit(key, part, slot)
            jobs.append(running[slot])
        else:
            jobs.append(submit(key, part))
    if config.executor == "local" or config.wait:
        waiting = [[job, key, part, 0] for job, (key, part) in zip(jobs, items)]
        while waiting:
            entry = waiting[0]
            job, key, part, resubmits = entry
            if not job_ended(job, config.executor):
                time.sleep(2)
                continue
            if _after_job(job, key, part, folders[key, part], config, resubmits, log):
                entry[0], entry[3] = submit(key, part), resubmits + 1
                jobs.append(entry[0])
            else:
                waiting.pop(0)
    return jobs


def part_folder(key: str, part: str, runs_dir: str, out: str) -> str:
    """The folder of part `part` of run `key` (its job file lies beside it)."""
    experiment, run = find_run(key)
    return os.path.join(run_state(experiment, run, runs_dir, out).folder, part)
