"""Experiments as code: each of the paper's tables and figures (and our own studies) is a named
`Experiment`, its training runs (`Run`: preset, overrides, seeds, budget) and a builder that makes its
table (markdown and JSON) and figure from the runs' `eval.json` and `metrics.csv`.

    python -m tools.experiments list                          # every experiment: runs done, partly trained, missing
    python -m tools.experiments list --max-seeds 1            # ... and the GPU time left at the logged speeds
    python -m tools.experiments run action-space --time-limit 540 --max-seeds 2   # train what is missing, then build
    python -m tools.experiments run sac-fast --parallel --max-seeds 1 --time-limit 540   # one part per local GPU
    python -m tools.experiments run sac-fast --parallel --round-robin --max-seeds 1   # a seed of every row first
    python -m tools.experiments commands reward               # one train.py command per run (cluster schedulers)
    python -m tools.experiments build                         # tables and figures from what is trained
    python -m tools.experiments record --runs-dir FETCHED/runs/experiments   # finished parts into the results, no table

A name selects an experiment (`action-space`) or one of its runs (`action-space/relative`); none selects all.
A run trains in parts, `<runs-dir>/<experiment>/<run>/seeds-<first>-<last>/` (a train.py logdir each, the seeds
trained together in one process; `--max-seeds K` caps them so that a part fits a time-limited call), and its state is
read from them: missing (nothing), partial (some progress), trained (at the budget, not evaluated), done (every
seed in a part whose `eval.json` the driver wrote at the end), changed (a part's `config.json` differs from the
registry's run in a field a resume may not change: move that part away to retrain it). Runs of different
experiments with equal training configs share the folder of the first one registered and train once; each
table takes its run's own seeds. An experiment's `cross` evaluations (a run's final policies on another env
setting, or with sampled actions) run as soon as each part is done, where its checkpoints are, into
`cross-<name>.json` beside `eval.json`. Tables and figures go to `<out>/<experiment>/` (`table.md`, `table.json`,
`curves.png`), and the build records the finished parts' config.json, eval.json and metrics.csv in
`<out>/<experiment>/runs/<run>/seeds-*/`, where the state is also read, so a checkout without the runs folder
knows what is done.

`run --time-limit S` returns within S seconds of its start (a 10 minute GPU call: `--time-limit 540`): each
training call gets the time left less the `--reserve` kept for the last checkpoint, the evaluation and exit as
its `stop_after_seconds` (the driver starts a chunk of updates only if it ends in time), and a part is not
started when its measured speed (its `metrics.csv`, or another part's of at least as many seeds) leaves no time
for one log interval. The next call resumes where this one stopped. A part stopped half way resumes only where
its checkpoints are: for the last call on a machine that will not keep `runs/`, `--whole-parts` trains only the
parts predicted to finish in the time left and leaves the others untouched, or `--carry-out DIR` packs its
runs' unfinished parts learner-only into DIR for the next machine's `--carry-in DIR` (`tools/carry_parts.py`).

The experiments are registered in `tools/experiment_registry.py` (types: `tools/experiment_spec.py`); this
module trains, lists and tabulates them. It imports only the standard library at the top, so the results
index can read the registry cheaply; configs, training and plots import jax on use.
"""

from __future__ import annotations

import argparse
import collections
import contextlib
import csv
import dataclasses
import datetime
import fcntl
import functools
import json
import math
import os
import shlex
import signal
import socket
import statistics
import subprocess
import sys
import time

from tools import experiment_registry  # noqa: F401  (registers the experiments in EXPERIMENTS)
from tools.experiment_spec import (  # noqa: F401  (re-exported: the registry's types, for callers and tests)
    EXPERIMENTS, MANAGED_FIELDS, Cross, Experiment, Run, apply_overrides, cli_option, register,
)

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
RUNS_DIR = os.path.join("runs", "experiments")
OUT_DIR = os.path.join("results", "experiments")
RATE_METRICS = ("target_reached", "self_collision", "obstacle_collision")
"""Metrics shown as percentages (rates in [0, 1] in eval.json and in `Run.paper`)."""
TIMING_COLUMNS = {"wall_clock": "training wall-clock (s)", "steps_per_second": "env steps/s per seed"}
"""Table columns read from metrics.csv instead of eval.json."""


def driver_metrics(units: list[dict]) -> dict:
    """{"per_seed": {eval.json key: [value per unit]}, "mean": {key: mean}} of evaluation units (`agents.evaluation`'s,
    in seed order) for the metrics a table may show: the driver's eval.json format."""
    per_seed = {key: [float(u["metrics"][name]) for u in units] for name, key in table_metrics().items()
                if all(name in u["metrics"] for u in units)}
    return {"per_seed": per_seed, "mean": {k: sum(v) / len(v) for k, v in per_seed.items()}}


def table_metrics() -> dict[str, str]:
    """Metric name -> eval.json key, for the metrics a table may show (besides `TIMING_COLUMNS`): the paper's and
    those of agents.evaluation.EXTRA_COLUMNS."""
    from agents.evaluation import EXTRA_COLUMNS, EXTRA_METRICS, PAPER_METRICS

    return {**PAPER_METRICS, **{name: EXTRA_METRICS[name] for name, _, _ in EXTRA_COLUMNS}}


# ------------------------------------------------------------------------------------------------
# Validation of a registered experiment (builds its configs; nothing compiles).


def validate_experiment(experiment: Experiment) -> None:
    """Builds and validates every run's TrainConfig (agents.config.validate; nothing compiles)."""
    from agents.config import validate
    from agents.evaluation import PAPER_METRICS, unseen_constants
    from agents.presets import PRESETS

    for run in experiment.runs:
        where = f"experiment {experiment.name!r}, run {run.name!r}"
        if run.preset not in PRESETS:
            raise ValueError(f"{where}: preset={run.preset!r} is unknown: allowed are {', '.join(sorted(PRESETS))}.")
        try:
            validate(run.config(logdir=os.path.join(RUNS_DIR, experiment.name, run.name)))
        except (ValueError, TypeError) as error:
            raise ValueError(f"{where}: {error}") from error
        unknown = [m for m in run.paper if m not in PAPER_METRICS]
        if unknown:
            raise ValueError(f"{where}: paper metric {unknown[0]!r} is unknown: allowed are {', '.join(PAPER_METRICS)}.")
    for cross in experiment.cross:
        where = f"experiment {experiment.name!r}, cross {cross.name!r}"
        run = experiment.run(cross.run)
        if not cross.name or any(not (c.isalnum() or c in "-_.") for c in cross.name):
            raise ValueError(f"{where}: name={cross.name!r} is invalid: allowed are letters, digits, '-', '_' and '.'.")
        if not cross.env and not cross.stochastic:
            raise ValueError(f"{where}: env={{}} with stochastic=False evaluates the run as trained again: allowed are "
                             "env fields to change, stochastic=True, or both.")
        unseen = unseen_constants(run.config().env, cross_env(run, cross, where))
        if unseen:
            raise ValueError(f"{where}: env={cross.env!r} changes what run {run.name!r} observed as one value in "
                             f"training: {'; '.join(unseen)}; allowed are crosses of runs that do not observe it "
                             "(drop it from the run's env.observation).")
    names = [c.name for c in experiment.cross]
    if len(set(names)) != len(names):
        raise ValueError(f"experiment {experiment.name!r} has crosses {names}: allowed are distinct names.")
    allowed = [*table_metrics(), *TIMING_COLUMNS]
    for m in experiment.metrics:
        if m not in allowed:
            raise ValueError(f"experiment {experiment.name!r}: metric {m!r} is unknown: allowed are "
                             f"{', '.join(allowed)}.")


# ------------------------------------------------------------------------------------------------
# State of a run, read from its folder.


def part_name(first: int, count: int) -> str:
    """Folder of seeds `first` .. `first + count - 1` of a run: "seeds-0-2"."""
    return f"seeds-{first}-{first + count - 1}"


def parse_part(name: str) -> tuple[int, int] | None:
    """(first seed, count) of a part folder name, None for any other name."""
    head, _, rest = name.partition("-")
    first, _, last = rest.partition("-")
    if head != "seeds" or not first.isdigit() or not last.isdigit() or int(last) < int(first):
        return None
    return int(first), int(last) - int(first) + 1


@dataclasses.dataclass
class PartState:
    """One train.py logdir of a run: some of its seeds, trained together in one process."""

    logdir: str
    first: int
    count: int
    status: str
    """missing, partial, trained, done or changed (see the module docstring)."""
    steps: int
    """Env steps per seed of the newest checkpoint (0 if none)."""
    budget: int
    rate: float | None = None
    """Measured env steps per second per seed (median over logged chunks after the first), None with fewer
    than two chunks logged."""
    startup: float | None = None
    """Seconds the first logged chunk took beyond its steps at `rate` (compilation, restore); with one chunk
    logged, that chunk's whole time (an upper bound); None if none logged."""
    wall_seconds: float = 0.0
    """Training wall-clock summed over logged chunks (compilation included)."""
    reason: str = ""

    @property
    def name(self) -> str:
        return part_name(self.first, self.count)

    @property
    def seeds(self) -> range:
        return range(self.first, self.first + self.count)


@dataclasses.dataclass
class RunState:
    """A run's state, gathered from the parts in its folder (and in the results' record of finished parts)."""

    experiment: str
    run: Run
    folder: str
    """Where its parts are trained: `<runs_dir>/<experiment>/<run>`, or the folder of the run it shares."""
    status: str
    """done (every seed of the run in a done part), partial (some progress), trained (at the budget, not
    evaluated), missing or changed."""
    steps: int
    """Env steps per seed reached by every seed not done yet (the budget when done)."""
    budget: int
    parts: list = dataclasses.field(default_factory=list)
    """PartState of each part found, by first seed."""
    shared: str = ""
    """"experiment/run" whose folder this run trains in (the first registered run with the same training
    config), "" for its own."""
    reason: str = ""

    @property
    def key(self) -> str:
        return f"{self.experiment}/{self.run.name}"

    @property
    def owner(self) -> tuple[str, str]:
        """(experiment, run) whose folder holds the parts."""
        return tuple((self.shared or self.key).split("/", 1))

    @property
    def done_parts(self) -> list:
        """The done parts that hold some of the run's seeds (0 .. run.seeds - 1), without overlaps, by first
        seed. A part of a shared folder may hold more seeds than this run has: `run_seeds` counts the run's."""
        chosen, covered = [], set()
        for part in sorted((p for p in self.parts if p.status == "done"), key=lambda p: (p.first, -p.count)):
            if part.first < self.run.seeds and not covered & set(part.seeds):
                chosen.append(part)
                covered |= set(part.seeds)
        return chosen

    def run_seeds(self, part) -> int:
        """How many of `part`'s seeds are this run's (its first ones): fewer than the part holds where the part is
        shared with a larger run. Its table row (`merged_evaluation`) and its figure line average these alone."""
        return min(part.count, self.run.seeds - part.first)

    @property
    def seeds_done(self) -> int:
        return sum(self.run_seeds(p) for p in self.done_parts)

    @property
    def wall_seconds(self) -> float:
        """Training wall-clock of one process, mean over the done parts with timings (compilation included); 0
        without any (a part recorded by tools.adopt_run --no-timing)."""
        parts = [p for p in self.done_parts if p.wall_seconds > 0]
        return sum(p.wall_seconds for p in parts) / len(parts) if parts else 0.0

    @property
    def rate(self) -> float | None:
        """Env steps/s per seed, mean over the done parts (parts of different seed counts run at different
        speeds per seed: `parts` has each)."""
        rates = [p.rate for p in self.done_parts if p.rate is not None]
        return sum(rates) / len(rates) if rates else None


def checkpoint_steps(logdir: str) -> list[int]:
    """Steps of the committed checkpoints in `logdir/checkpoints` (orbax's temporary folders are not)."""
    directory = os.path.join(logdir, "checkpoints")
    if not os.path.isdir(directory):
        return []
    return sorted(int(d) for d in os.listdir(directory) if d.isdigit() and os.path.isdir(os.path.join(directory, d)))


def read_timing(logdir: str, seeds: int) -> tuple[float | None, float | None, float]:
    """(env steps/s per seed, startup seconds, wall-clock seconds) from metrics.csv: one row per logged
    chunk (the seeds' rows share the speed; rows of no positive, finite speed are skipped); a resumed run's
    re-logged steps count once. The speed is the median over the chunks after the first (which holds the
    compilation; the first chunk of each later call, a resume, stays in: with many chunks a call it moves the
    median little): None with one chunk only, whose time then bounds the start-up. None, None, 0 without
    chunks."""
    path = os.path.join(logdir, "metrics.csv")
    if not os.path.isfile(path):
        return None, None, 0.0
    chunks: dict[int, tuple[float, float]] = {}
    with open(path, newline="") as f:
        for row in csv.DictReader(f):
            try:
                rate, wall = float(row["steps_per_second"]), float(row["wall_seconds"])
                if math.isfinite(rate) and rate > 0 and math.isfinite(wall):
                    chunks[int(float(row["env_steps"]))] = (rate, wall)
            except (KeyError, TypeError, ValueError):
                continue
    if not chunks:
        return None, None, 0.0
    steps = sorted(chunks)
    wall = sum(w for _, w in chunks.values())
    if len(steps) == 1:
        return None, chunks[steps[0]][1], wall
    rate = statistics.median(chunks[s][0] / seeds for s in steps[1:])
    return rate, max(0.0, chunks[steps[0]][1] - steps[0] / rate), wall


def part_state(run: Run, logdir: str, first: int, count: int) -> PartState:
    """The state of seeds `first` .. `first + count - 1` of `run` from the files in `logdir`."""
    budget = run.budget()
    steps = (checkpoint_steps(logdir) or [0])[-1]
    rate, startup, wall = read_timing(logdir, count)
    state = PartState(logdir, first, count, "missing", steps, budget, rate, startup, wall)
    stored = os.path.join(logdir, "config.json")
    if os.path.isfile(stored):
        reason = config_difference(run.config(logdir, first_seed=first, seeds=count), stored)
        if reason:
            state.status, state.reason = "changed", reason
            return state
    if os.path.isfile(os.path.join(logdir, "eval.json")):
        with open(os.path.join(logdir, "eval.json")) as f:
            evaluated = json.load(f).get("env_steps", 0)
        if evaluated >= budget:
            state.status, state.steps = "done", max(steps, evaluated)
            return state
    if steps >= budget:
        state.status = "trained"
    elif steps > 0:
        state.status = "partial"
    return state


_RECIPES: dict[int, tuple[Run, str]] = {}


def recipe(run: Run) -> str:
    """The run's training config as canonical JSON, seeds and logdir left out: runs with equal recipes train
    the same thing."""
    cached = _RECIPES.get(id(run))
    if cached is None or cached[0] is not run:
        from agents.config import config_json

        text = json.dumps(config_json(dataclasses.replace(run.config(), seeds=1)), sort_keys=True)
        cached = _RECIPES[id(run)] = (run, text)
    return cached[1]


def storage(experiment: Experiment, run: Run, registry: dict | None = None) -> tuple[str, str]:
    """(experiment, run) whose folder trains `run`: the first run of the registry with the same recipe (so an
    experiment's baseline that another experiment also has trains once), else the run's own."""
    registry = EXPERIMENTS if registry is None else registry
    if registry.get(experiment.name) is experiment:
        key = recipe(run)
        for exp in registry.values():
            for other in exp.runs:
                if other is run or recipe(other) == key:
                    return exp.name, other.name
    return experiment.name, run.name


def run_folders(selection: list[tuple[Experiment, list[Run]]]) -> list[str]:
    """The `<experiment>/<run>` folders (under a runs folder) that train the selected runs (`storage`)."""
    return sorted({"/".join(storage(exp, run)) for exp, runs in selection for run in runs})


def record_folder(record: str, experiment: str, run: str) -> str:
    """Where a build keeps the finished parts' config.json, eval.json and metrics.csv (in git, with the table)."""
    return os.path.join(record, experiment, "runs", run)


def run_state(experiment: Experiment, run: Run, runs_dir: str, record: str | None = None,
              registry: dict | None = None) -> RunState:
    """The run's state from its parts in `<runs_dir>/<experiment>/<run>/seeds-A-B/` (the folder of the run it
    shares, if any) and, for parts finished elsewhere, in the record under `record` (results/experiments)."""
    owner = storage(experiment, run, registry)
    folder = os.path.join(runs_dir, *owner)
    places = [folder] + ([record_folder(record, *owner)] if record else [])
    found: dict[tuple[int, int], PartState] = {}
    for place in places:
        if not os.path.isdir(place):
            continue
        for name in sorted(os.listdir(place)):
            span = parse_part(name)
            if span is None or not os.path.isdir(os.path.join(place, name)):
                continue
            part = part_state(run, os.path.join(place, name), *span)
            # The training folder wins unless only the record holds the finished part.
            if span not in found or (part.status == "done" and found[span].status != "done"):
                found[span] = part
    parts = sorted(found.values(), key=lambda p: (p.first, p.count))
    shared = "" if owner == (experiment.name, run.name) else "/".join(owner)
    state = RunState(experiment.name, run, folder, "missing", 0, run.budget(), parts, shared)
    needed = set(range(run.seeds))
    done = {s for p in state.done_parts for s in p.seeds}
    # A changed part blocks the run only where no done part holds its seeds (an outdated record part does not).
    changed = [p for p in parts if p.status == "changed" and (needed - done) & set(p.seeds)]
    if changed:
        state.status, state.reason = "changed", f"{changed[0].name}: {changed[0].reason}"
        state.steps = changed[0].steps
        return state
    if os.path.isfile(os.path.join(folder, "config.json")):
        state.reason = f"{folder} holds a train.py run outside any seeds-* part: ignored (move it into a part to use it)"
    if needed <= done:
        state.status, state.steps = "done", state.budget
        return state
    reached = [max([p.steps for p in parts if s in p.seeds] or [0]) for s in sorted(needed - done)]
    state.steps = min(reached)
    if state.steps >= state.budget:
        state.status = "trained"
    elif done or max(reached) > 0:
        state.status = "partial"
    return state


def pending_parts(state: RunState, max_seeds: int | None = None) -> list[PartState]:
    """The parts still to train for `state.run`'s seeds: unfinished parts that hold some of them (resumed as
    they are), then new parts of at most `max_seeds` seeds (None: all the rest in one) for the seeds no part
    holds yet."""
    needed = set(range(state.run.seeds))
    done = {s for p in state.done_parts for s in p.seeds}
    todo = [p for p in state.parts if p.status in ("partial", "trained", "missing") and (needed - done) & set(p.seeds)]
    free = sorted(needed - done - {s for p in todo for s in p.seeds})
    runs: list[list[int]] = []
    for seed in free:
        if runs and seed == runs[-1][-1] + 1 and (max_seeds is None or len(runs[-1]) < max_seeds):
            runs[-1].append(seed)
        else:
            runs.append([seed])
    return todo + [PartState(os.path.join(state.folder, part_name(r[0], len(r))), r[0], len(r), "missing", 0,
                             state.budget) for r in runs]


def cross_env(run: Run, cross: Cross, where: str = ""):
    """The run's env config with the cross-evaluation's fields; ValueError naming an unknown field or a value
    the env refuses."""
    import envs

    config = run.config()
    allowed = [f.name for f in dataclasses.fields(config.env)]
    unknown = [k for k in cross.env if k not in allowed]
    if unknown:
        raise ValueError(f"{where or cross.name}: env field {unknown[0]!r} is unknown for {config.env_name}: allowed "
                         f"are {', '.join(allowed)}.")
    env = dataclasses.replace(config.env, **{k: tuple(v) if isinstance(v, list) else v for k, v in cross.env.items()})
    envs.registry.check_config(config.env_name, env)
    return env


def cross_path(part: PartState, cross: Cross, record_dir: str | None = None) -> str | None:
    """The part's cross-<name>.json (beside its logdir's eval.json, else in the record), None if not made yet."""
    for folder in (part.logdir, *([os.path.join(record_dir, part.name)] if record_dir else [])):
        path = os.path.join(folder, f"cross-{cross.name}.json")
        if os.path.isfile(path):
            return path
    return None


def cross_evaluate(run: Run, part: PartState, cross: Cross) -> str:
    """Evaluates the part's final checkpoint on the cross setting (the run's eval_envs episodes per seed, its
    eval_seed; the policy's mode unless `cross.stochastic`) and writes `cross-<name>.json` in eval.json's format;
    returns the path."""
    from agents import evaluation
    from agents.checkpoint import write_atomic

    config = run.config(part.logdir, first_seed=part.first, seeds=part.count)
    result = evaluation.run(evaluation.checkpoint_policy(part.logdir), config.env_name, cross_env(run, cross),
                            num_envs=config.eval_envs, eval_seeds=(config.eval_seed,), stochastic=cross.stochastic)
    path = os.path.join(part.logdir, f"cross-{cross.name}.json")
    write_atomic(path, json.dumps({"env_steps": part.steps, "eval_envs": config.eval_envs, "env": cross.env,
                                   "actions": "stochastic" if cross.stochastic else "deterministic",
                                   **driver_metrics(result.units)}, indent=2))
    return path


def pending_crosses(experiment: Experiment, state: RunState, record: str | None = None) -> list[tuple[PartState, Cross]]:
    """(part, cross) pairs still to evaluate for `state.run`: done parts with their checkpoints at hand."""
    record_dir = record_folder(record, *state.owner) if record else None
    return [(part, cross) for cross in experiment.cross if cross.run == state.run.name for part in state.done_parts
            if cross_path(part, cross, record_dir) is None and checkpoint_steps(part.logdir)]


def folder_crosses(experiment: Experiment, state: RunState, runs_dir: str, record: str | None = None,
                   registry: dict | None = None) -> list[tuple[Run, RunState, PartState, Cross]]:
    """(run, its state, part, cross) still to evaluate on the done parts in `state`'s folder: the crosses of
    `state.run` and of the registered runs that train in the same folder (`storage`: the same training config),
    which use the same checkpoints."""
    registry = EXPERIMENTS if registry is None else registry
    pairs = [(experiment, state.run, state)]
    for exp in registry.values():
        pairs += [(exp, r, run_state(exp, r, runs_dir, record, registry)) for r in exp.runs
                  if r is not state.run and exp.cross and storage(exp, r, registry) == state.owner]
    return [(run, st, part, cross) for exp, run, st in pairs for part, cross in pending_crosses(exp, st, record)]


def config_difference(config, path: str) -> str:
    """"" if the config stored at `path` may be resumed as `config`, else which field differs."""
    from agents.config import merge_resume_config, read_config

    try:
        saved = read_config(path)
        merge_resume_config(config, saved)
    except ValueError as error:
        return str(error)
    if saved.seeds != config.seeds:
        return f"seeds={config.seeds} differs from the stored {saved.seeds}"
    return ""


def select(names: list[str] | None, experiments: dict | None = None) -> list[tuple[Experiment, list[Run]]]:
    """(experiment, runs) for each name: an experiment, or experiment/run; no names: everything."""
    experiments = EXPERIMENTS if experiments is None else experiments
    out: dict[str, tuple[Experiment, list[Run]]] = {}
    for name in names or list(experiments):
        exp_name, _, run_name = name.partition("/")
        if exp_name not in experiments:
            raise ValueError(f"experiment {exp_name!r} is unknown: allowed are {', '.join(experiments)}.")
        exp = experiments[exp_name]
        runs = [exp.run(run_name)] if run_name else list(exp.runs)
        chosen = out.setdefault(exp_name, (exp, []))[1]
        chosen += [r for r in runs if r not in chosen]
    return list(out.values())


def table_built(experiment: Experiment, out: str) -> bool:
    return os.path.isfile(os.path.join(out, experiment.name, "table.json"))


# ------------------------------------------------------------------------------------------------
# list and commands.


def millions(steps: float) -> str:
    return f"{steps / 1e6:g}M"


def describe_state(st: RunState) -> str:
    """'done', 'partial 2/5 seeds done, 60M/150M', 'changed (...)', with the run it shares."""
    text = st.status
    if st.status == "partial":
        done = f"{st.seeds_done}/{st.run.seeds} seeds done" if st.seeds_done else ""
        text += " " + ", ".join(x for x in (done, f"{millions(st.steps)}/{millions(st.budget)}" if st.steps else "") if x)
    if st.reason:
        text += f" ({st.reason})"
    return text + (f" [trains in {st.shared}]" if st.shared else "")


def gpu_time(seconds: float) -> str:
    """"~45 GPU-min", "~6.2 GPU-h", "<1 GPU-min"."""
    minutes = seconds / 60
    if minutes < 1:
        return "<1 GPU-min"
    return f"~{minutes:.0f} GPU-min" if minutes < 120 else f"~{minutes / 60:.1f} GPU-h"


def time_note(seconds: float, unknown: int) -> str:
    """What `time_left` predicts, for the listing: '~45 GPU-min left at logged speeds' (+ the parts it could not
    time)."""
    untimed = f"{unknown} part{'s' * (unknown != 1)} of presets never timed here"
    if not seconds:
        return untimed if unknown else "nothing left"
    return f"{gpu_time(seconds)} left at logged speeds" + (f" + {untimed}" if unknown else "")


def listing(selection, runs_dir: str, out: str, registry: dict | None = None, max_seeds: int | None = None) -> str:
    """Every selected experiment with its runs' states, the env steps they cost (a folder shared by several runs
    counted once, with the most seeds any of them needs) and the GPU time left to train them (`time_left`, the
    parts planned as `run --max-seeds max_seeds` would, each folder by the run that plans it)."""
    lines, need, trained = [], {}, {}
    planner = {st.folder: st.key for _, st in planners(selection, runs_dir, out, registry)}
    total_seconds, total_unknown = 0.0, 0
    for exp, runs in selection:
        states = [run_state(exp, r, runs_dir, out, registry) for r in runs]
        counts = {s: sum(st.status == s for st in states) for s in ("done", "trained", "partial", "missing", "changed")}
        summary = ", ".join(f"{n} {s}" for s, n in counts.items() if n)
        seconds, unknown = 0.0, 0
        for st in states:
            if st.status != "done" and planner.get(st.folder) == st.key:
                more, none = time_left(st, runs_dir, out, registry, max_seeds)
                seconds, unknown = seconds + more, unknown + none
        total_seconds, total_unknown = total_seconds + seconds, total_unknown + unknown
        lines.append(f"{exp.name}: {exp.title} [{exp.paper_ref}]")
        lines.append(f"  {summary}; table {'built' if table_built(exp, out) else 'not built'}"
                     + (f"; {time_note(seconds, unknown)}" if seconds or unknown else ""))
        for st in states:
            need[st.folder] = max(need.get(st.folder, 0), st.run.seeds * st.budget)
            reached: dict[int, int] = {}  # per seed, the furthest part holding it (parts may overlap)
            for p in st.parts:
                if p.status != "changed":
                    for seed in p.seeds:
                        reached[seed] = max(reached.get(seed, 0), min(p.steps, p.budget))
            trained[st.folder] = max(trained.get(st.folder, 0), sum(reached.values()))
            lines.append(f"  {st.run.name:22s} {st.run.preset:26s} {st.run.seeds} x {millions(st.budget):>6s}  "
                         f"{describe_state(st)}")
        by_name = {st.run.name: st for st in states}
        for cross in exp.cross:
            st = by_name.get(cross.run) or run_state(exp, exp.run(cross.run), runs_dir, out, registry)
            files = cross_files(st, cross, out)
            left = [p for p in st.done_parts if p.name not in files]
            here = sum(bool(checkpoint_steps(p.logdir)) for p in left)
            status = ("after training" if not st.done_parts else "done" if st.status == "done" and not left else
                      f"{len(files)} of {len(st.done_parts)} parts evaluated; {here} to evaluate here (`run`), "
                      f"{len(left) - here} without checkpoints here (evaluated where they are, or retrained)")
            lines.append(f"  cross {cross.name}: {cross.run} with {cross.setting}: {status}")
    total = sum(need.values())
    done = sum(min(trained[f], need[f]) for f in need)
    lines.append(f"total: {total:,} env steps ({total / 1e9:.2f}B), {done:,} trained; "
                 + time_note(total_seconds, total_unknown) + (f" (--max-seeds {max_seeds})" if max_seeds else
                                                             " (all of a run's seeds in one part)"))
    return "\n".join(lines)


def planners(selection, runs_dir: str, record: str | None = None, registry: dict | None = None,
             with_changed: bool = False) -> list[tuple[Experiment, RunState]]:
    """(experiment, state) of the run that plans each selected folder's parts: of runs sharing a folder, the one
    needing the most seeds, so no seed is planned twice. Changed runs only `with_changed`."""
    by_folder: dict[str, tuple[Experiment, RunState]] = {}
    for exp, runs in selection:
        for run in runs:
            st = run_state(exp, run, runs_dir, record, registry)
            if st.status == "changed" and not with_changed:
                continue
            if st.folder not in by_folder or run.seeds > by_folder[st.folder][1].run.seeds:
                by_folder[st.folder] = (exp, st)
    return list(by_folder.values())


def commands(selection, runs_dir: str, everything: bool = False, max_seeds: int | None = None,
             record: str | None = None, registry: dict | None = None) -> list[str]:
    """One `python train.py ...` per part still to train (with `everything`, every part of every run, each as a
    fresh run); unfinished parts get --resume. Runs sharing a folder are planned once (`planners`)."""
    lines = []
    for _, st in planners(selection, runs_dir, record, registry, with_changed=everything):
        if everything:
            st = dataclasses.replace(st, parts=[])
        for part in pending_parts(st, max_seeds):
            args = st.run.train_args(part.logdir, resume=part.steps > 0 and not everything, first_seed=part.first,
                                     seeds=part.count)
            if part.steps == 0 and os.path.isdir(part.logdir) and os.listdir(part.logdir):
                args.append("--overwrite")  # stopped before its first checkpoint: only logs to replace
            lines.append(shlex.join(["python", "train.py", *args]))
    return lines


# ------------------------------------------------------------------------------------------------
# Training within a time limit.


ASSUMED_STARTUP = 60.0
"""Seconds of start-up assumed for a part whose start-up was never measured (nor a comparable part's):
compilation and, for an off-policy learner, the replay buffer's first fill (about a minute for fast SAC:
results/experiments/README.md)."""

ASSUMED_CROSS = 45.0
"""Seconds assumed for a call's first cross-evaluation, before one is timed: like the evaluation at the end of
training, it compiles the policy's rollout and runs `eval_envs` episodes per seed (the evaluations' times in the
workers' logs: results/experiments/sac-fast/calls/2026-11-27d_calls.md). One started with less time left is
cut off by the `--parallel` driver's SIGINT past the deadline and lost."""

PROCESS_START = 10.0
"""Seconds a part spends outside metrics.csv's clock, which every measured start-up leaves out: the process's
imports, building the env and the learner, restoring a checkpoint (~9 s for a one-seed UR5e reach part on an
H200: its worker's own clock against its chunks' wall-clock sum). Added to `--whole-parts`' prediction for every
part that starts up, a margin for a part that must finish; `time_left`, a planning figure, leaves it out."""


def may_start(part: PartState, seconds: float | None, compiled: bool, startup_guess: float | None = None,
              rate_guess: float | None = None) -> bool:
    """Whether a training call of `part` with `seconds` left (None: no limit) is worth its start-up, which a
    part stopped half way pays again at its resume: it must train at least as long as it starts up, and at
    least one log interval, at its measured speed (its own, else `rate_guess`), unless it finishes sooner;
    without a speed, the time left must exceed twice the start-up (measured, guessed from a comparable part,
    else `ASSUMED_STARTUP`). The call then trains to its budget or until the driver's clock
    (`stop_after_seconds`) stops it, never to a predicted step: a prediction from a slower start-up (one
    compiled without the cache) would end it early, and each restart costs a compilation and, for an
    off-policy learner, a refill of its replay buffer."""
    if seconds is None:
        return True
    if seconds <= 0:
        return False
    rate, startup = _speed(part, compiled, startup_guess, rate_guess)
    if rate is None:
        return seconds > 2 * startup
    interval = max(1, part.budget // 50)  # the driver's default log interval
    to_finish = (part.budget - part.steps) / rate
    return seconds - startup >= min(to_finish, max(startup, interval / rate))


def seconds_to_finish(part: PartState, compiled: bool, startup_guess: float | None = None,
                      rate_guess: float | None = None) -> float | None:
    """Predicted seconds to train `part` from its checkpoint to its budget (startup included unless `compiled`),
    at its own measured speed per seed, else `rate_guess`; None without a speed."""
    rate, startup = _speed(part, compiled, startup_guess, rate_guess)
    return startup + (part.budget - part.steps) / rate if rate else None


def _speed(part: PartState, compiled: bool, startup_guess: float | None,
           rate_guess: float | None) -> tuple[float | None, float]:
    """(env steps/s per seed, startup seconds) of `part`'s next call: its own measurements, else the guesses
    (else `ASSUMED_STARTUP`); no startup once its program is compiled in this process."""
    rate = part.rate if part.rate is not None else rate_guess
    if compiled:
        return rate, 0.0
    known = [x for x in (part.startup, startup_guess) if x is not None]
    return rate, known[0] if known else ASSUMED_STARTUP


def longest(*startups: float | None) -> float | None:
    """The longest of the start-ups known (None: not measured), None if none is."""
    return max((x for x in startups if x is not None), default=None)


def speed_guess(state: RunState, part: PartState, peers=()) -> tuple[float | None, float | None]:
    """(env steps/s per seed, startup s) measured on another part of the run (or among `peers`, parts of
    comparable runs: `comparable_parts`; parts trained under a changed config left out): the slowest speed of the
    parts with as many seeds, else of those with more (seeds trained together run no faster per seed than fewer,
    and much slower than alone: one UR5e reach seed ~880k env steps/s, each of three ~440k), and the longest
    start-up among the same parts (start-ups differ between parts of one config, a compilation cache hit or not:
    a part that must finish is planned on the worst of both), or (None, None)."""
    measured = [p for p in [*state.parts, *peers] if p.rate is not None and p.count >= part.count
                and p.logdir != part.logdir and p.status != "changed"]
    if not measured:
        return None, None
    chosen = [p for p in measured if p.count == part.count] or measured
    return min(p.rate for p in chosen), longest(*(p.startup for p in chosen))


def speed_key(run: Run) -> str:
    """The run's `recipe` without its budget and seed: runs with equal keys train at the same speed."""
    fields = json.loads(recipe(run))
    del fields["num_timesteps"], fields["seed"]
    return json.dumps(fields, sort_keys=True)


def parts_of_runs_like(run: Run, alike, runs_dir: str, record: str | None = None, registry: dict | None = None) -> list:
    """The parts of the other registered runs for which `alike(other)` holds."""
    registry = EXPERIMENTS if registry is None else registry
    return [part for exp in registry.values() for other in exp.runs if other is not run and alike(other)
            for part in run_state(exp, other, runs_dir, record, registry).parts]


def comparable_parts(run: Run, runs_dir: str, record: str | None = None, registry: dict | None = None) -> list:
    """The parts of the other registered runs that train what `run` trains, budget apart (`speed_key`): their
    measured speeds stand in for a run that has none of its own yet (`speed_guess`)."""
    key = speed_key(run)
    return parts_of_runs_like(run, lambda other: speed_key(other) == key, runs_dir, record, registry)


def learner_key(run: Run) -> str:
    """The run's preset, learner config (network sizes, epochs, envs, ...) and physics cost (the env's substeps
    and backend), without the rest of its env config (observation, reward terms, workspace, obstacles, episode
    length) and the top-level fields (evaluation, precision): these move the speed less than the network's size
    does (3x512 against 3x256: 1.2-1.5x the time, results/experiments/network-size), and a rough guess takes the
    slowest part."""
    fields = json.loads(recipe(run))
    physics = {name: fields["env"].get(name) for name in ("substeps", "backend")}
    return json.dumps([run.preset, fields["algo_name"], fields["algo"], physics], sort_keys=True)


def same_learner_parts(run: Run, runs_dir: str, record: str | None = None, registry: dict | None = None) -> list:
    """The parts of the other registered runs of `run`'s preset and learner config (`learner_key`), whatever their
    env overrides: `guess_speed(rough=True)`'s first stand-in, before the whole preset's."""
    key = learner_key(run)
    return parts_of_runs_like(run, lambda other: learner_key(other) == key, runs_dir, record, registry)


def same_preset_parts(run: Run, runs_dir: str, record: str | None = None, registry: dict | None = None) -> list:
    """The parts of the other registered runs of `run`'s preset, whatever their overrides: a rough stand-in speed
    for estimates (`time_left`) and for `--whole-parts`' prediction of a config never timed, never for
    `may_start`'s."""
    return parts_of_runs_like(run, lambda other: other.preset == run.preset, runs_dir, record, registry)


def guess_speed(st: RunState, part: PartState, runs_dir: str, record: str | None = None,
                registry: dict | None = None, rough: bool = False) -> tuple[float | None, float | None]:
    """(env steps/s per seed, startup s) for `part` when it has none of its own: another part's of its run, else
    of a run training the same config (`comparable_parts`), each with at least as many seeds (`speed_guess`);
    with `rough`, then of a run of the same preset and learner config (`same_learner_parts`: the env's overrides
    move the speed little), then of any run of the preset (`same_preset_parts`; with as many seeds, it comes
    before a same-learner part of fewer), and last a part of any of these with fewer seeds, its throughput in all
    shared among `part`'s seeds (vmapping more seeds has never lowered the throughput in all:
    results/sac/brax_reference, results/experiments; for the same config a time from it is an upper bound, for
    another config of the preset a rough one); (None, None) where none was measured."""
    rate, startup = speed_guess(st, part)
    if part.rate is not None or rate is not None:
        return rate, startup
    comparable = comparable_parts(st.run, runs_dir, record, registry)
    rate, startup = speed_guess(st, part, comparable)
    if not rough or rate is not None:
        return rate, startup
    rate, startup = speed_guess(st, part, same_learner_parts(st.run, runs_dir, record, registry))
    if rate is not None:
        return rate, startup
    preset = same_preset_parts(st.run, runs_dir, record, registry)
    rate, startup = speed_guess(st, part, preset)
    if rate is not None:
        return rate, startup
    fewer = [p for p in [*st.parts, *comparable, *preset]
             if p.rate is not None and p.status != "changed" and p.logdir != part.logdir]
    if not fewer:
        return None, None
    slowest = min(fewer, key=lambda p: p.rate * p.count)
    return slowest.rate * slowest.count / part.count, longest(*(p.startup for p in fewer))


def time_left(st: RunState, runs_dir: str, record: str | None = None, registry: dict | None = None,
              max_seeds: int | None = None) -> tuple[float, int]:
    """(seconds, parts without a speed): one GPU's time to train the run's pending parts (`pending_parts` with
    `max_seeds`), each from its checkpoint with one start-up, at its measured speed, else `guess_speed(rough=True)`
    (speeds differ between GPU models and vary with the overrides: a planning figure, not a promise)."""
    seconds, unknown = 0.0, 0
    for part in pending_parts(st, max_seeds):
        rate, startup = guess_speed(st, part, runs_dir, record, registry, rough=True)
        need = seconds_to_finish(part, False, startup, rate)
        if need is None:
            unknown += 1
        else:
            seconds += need
    return seconds, unknown


def start_verdict(st: RunState, part: PartState, seconds: float | None, compiled: bool,
                  startup_seen: float | None, whole_parts: bool, runs_dir: str, record: str | None = None,
                  registry: dict | None = None) -> tuple[str, str]:
    """Whether `part` of run state `st` starts with `seconds` left after the reserve (None: no limit): ("start",
    ""), ("later", why) where `whole_parts` predicts it cannot finish (the next run is tried), or ("stop", why)
    where `may_start` refuses it. Its speed is its own, else a part's of its run or of a comparable run
    (`speed_guess`); its start-up the longest of that guess and `startup_seen` (this call's). With none of these,
    `whole_parts` predicts from `guess_speed(rough=True)` (other runs of its preset) rather than leave the GPU
    idle, and starts the part where the prediction fits; `may_start` never uses a rough guess. Used by a training
    process before each part and by the `--parallel` driver before it starts a worker (a worker that would stop
    at once still costs its process start, 10-20 s past the parts' stop)."""
    rate_guess, startup_guess = guess_speed(st, part, runs_dir, record, registry)
    startup_guess = longest(startup_seen, startup_guess)
    if whole_parts and seconds is not None:
        need, rough = seconds_to_finish(part, compiled, startup_guess, rate_guess), ""
        if need is None:  # better a rough guess than an idle GPU: a part it misjudges stops with the call
            rate, startup = guess_speed(st, part, runs_dir, record, registry, rough=True)
            need = seconds_to_finish(part, compiled, longest(startup, startup_seen), rate)
            rough = " (a rough guess from other runs of its preset)" if need is not None else ""
        if need is not None and not compiled:
            need += PROCESS_START
        if need is None or need > seconds:
            return "later", (f"left for a later call: it needs "
                             f"{'an unknown time (no speed measured)' if need is None else f'~{need:.0f} s'}{rough} "
                             f"to finish, {max(0.0, seconds):.0f} s are left")
        return "start", ""  # predicted to finish: worth its start-up whatever `may_start` would guess
    if not may_start(part, seconds, compiled, startup_guess, rate_guess):
        return "stop", f"time limit: stopped at {part.steps:,} of {part.budget:,} steps; run again to continue"
    return "start", ""


def lock_path(logdir: str) -> str:
    """The lock file of part folder `logdir`: `<run folder>/.<part>.lock`, beside the part (not in it, which a
    fresh start may clear and `tools.carry_parts` packs)."""
    return os.path.join(os.path.dirname(logdir), f".{os.path.basename(logdir)}.lock")


@contextlib.contextmanager
def part_lock(logdir: str):
    """Holds an exclusive `flock` on the part's lock file while the part trains (or is packed), so that two
    commands sharing a runs folder never work on one part at once. The kernel drops the lock when its process
    ends, even killed, so a leftover file holds nothing. Yields None while held, or why the part is taken (the
    holder's pid and host, which it writes into the file for this message)."""
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


def train_pending(selection, runs_dir: str, deadline: float | None = None, reserve: float = 0.0,
                  log=print, learner_cls=None, max_seeds: int | None = None, record: str | None = None,
                  registry: dict | None = None, whole_parts: bool = False, record_each: bool = False,
                  only_part: str | None = None) -> bool:
    """Trains the selected runs that are not done, in order, part by part (at most `max_seeds` seeds per
    train.py process), resuming unfinished parts; returns True when every selected run is done, False when
    the deadline (time.monotonic) or a changed run stopped it. `whole_parts`: with a deadline, a part is
    trained only if it is predicted to reach its budget in time (`seconds_to_finish`); the others, and parts
    of unknown speed, are left for later and the next run is tried. For a machine that will not outlive the
    call, where a part stopped half way would be lost. `record_each`: a part's files are recorded in `record`
    as soon as it is done (`record_parts`), so a call killed later still brings them back. `only_part` (a part
    name, `seeds-<first>-<last>`, of the one selected run): that part alone, with its cross-evaluations, as a
    `train_parallel` worker trains it beside workers training the run's other parts; then True means that part
    is done and evaluated (not the whole run), False that it is not (or that no such part is planned)."""
    from agents import driver

    compiled: set[str] = set()
    startup_seen: float | None = None  # the longest start-up measured in this call
    cross_seconds = 0.0  # the longest cross-evaluation of this call
    finished = True

    def record_part(state: RunState, name: str) -> None:
        if record_each and record is not None:
            for path in record_parts(state, record, only=name):
                log(f"recorded {path}")

    for exp, runs in selection:
        for run in runs:
            while True:
                st = run_state(exp, run, runs_dir, record, registry)
                # Each done part's cross-evaluations (this run's, and those of runs sharing its folder) run while
                # its checkpoints are at hand: this machine may not keep them for the rest of the run.
                for run_x, st_x, part, cross in folder_crosses(exp, st, runs_dir, record, registry):
                    if only_part is not None and part.name != only_part:
                        continue  # another worker's part
                    if deadline is not None and deadline - time.monotonic() < max(cross_seconds or ASSUMED_CROSS,
                                                                                  reserve / 2):
                        log(f"[{st_x.key} {part.name}] time limit: cross-evaluation {cross.name!r} left for the next call")
                        return False
                    with part_lock(part.logdir) as taken:
                        # Under the part's lock, and looked for again: two drivers given one row would otherwise
                        # both evaluate a part that one of them trained.
                        if taken is None and cross_path(part, cross) is None:
                            log(f"[{st_x.key} {part.name}] cross-evaluation {cross.name!r}: {cross.setting}")
                            t0 = time.monotonic()
                            cross_evaluate(run_x, part, cross)
                            cross_seconds = max(cross_seconds, time.monotonic() - t0)
                    if taken is not None:
                        log(f"[{st_x.key} {part.name}] cross-evaluation {cross.name!r} left alone: {taken}")
                        finished = False
                        continue
                    record_part(st_x, part.name)
                if st.status == "done":
                    break
                if st.status == "changed":
                    log(f"[{st.key}] skipped: {st.reason}; move that part away to retrain it")
                    finished = False
                    break
                planned = pending = pending_parts(st, max_seeds)
                if only_part is not None:
                    if any(p.name == only_part for p in st.done_parts):
                        break
                    pending = [p for p in planned if p.name == only_part]
                    if not pending:
                        log(f"[{st.key}] no part {only_part} to train: its parts are "
                            f"{', '.join(p.name for p in planned)}"
                            + (f" (with --max-seeds {max_seeds})" if max_seeds is not None else ""))
                        finished = False
                        break
                part = pending[0]
                where = f"[{st.key} {part.name}" + (f" in {st.shared}]" if st.shared else "]")
                seconds = None if deadline is None else deadline - time.monotonic() - reserve
                is_compiled = part.logdir in compiled
                verdict, why = start_verdict(st, part, seconds, is_compiled, startup_seen, whole_parts, runs_dir,
                                             record, registry)
                if verdict == "later":
                    log(f"{where} {why}")
                    finished = False
                    break
                if verdict == "stop":
                    log(f"{where} {why}")
                    return False
                result = None
                with part_lock(part.logdir) as taken:
                    # Read again under the lock: another command may have trained it since `st` was read.
                    part = part_state(run, part.logdir, part.first, part.count) if taken is None else part
                    if taken is None and part.status not in ("done", "changed"):
                        resume = part.steps > 0
                        # A part stopped before its first checkpoint (a killed call) left config.json and logs:
                        # start it afresh.
                        fresh_over = not resume and os.path.isdir(part.logdir) and bool(os.listdir(part.logdir))
                        log(f"{where} {'resuming at ' + format(part.steps, ',') if resume else 'starting'}; "
                            f"to the end of {part.budget:,} steps x {part.count} seeds"
                            + ("" if seconds is None else f" or {seconds:.0f} s"))
                        t0 = time.monotonic()
                        config = run.config(part.logdir, first_seed=part.first, seeds=part.count, resume=resume,
                                            overwrite=fresh_over, stop_after_steps=0,
                                            stop_after_seconds=seconds or 0.0)
                        result = driver.train(config, learner_cls)
                if taken is not None:
                    log(f"{where} left alone: {taken}")
                    finished = False
                    break  # the run's later parts wait for the next call, as after a time limit
                if result is None:
                    continue  # done or changed by another command meanwhile: read the run again
                if part.logdir not in compiled:
                    measured = part_state(run, part.logdir, part.first, part.count).startup
                    if measured is not None:
                        startup_seen = max(startup_seen or 0.0, measured)
                compiled.add(part.logdir)
                log(f"{where} {result.status} at {result.env_steps:,} steps after {time.monotonic() - t0:.0f} s")
                if result.status == "done":
                    record_part(run_state(exp, run, runs_dir, record, registry), part.name)
                if result.status == "interrupted":
                    log(f"{where} interrupted: checkpoint saved at {result.env_steps:,} steps")
                    return False
                if result.status != "done" and result.env_steps <= part.steps:
                    return False
    return finished


def local_gpus() -> list[str]:
    """The GPUs this process may use, as CUDA_VISIBLE_DEVICES names them for its workers: that variable's
    entries where it is set (so two drivers can share a host: `CUDA_VISIBLE_DEVICES=2,3 ... run --parallel`),
    else every GPU `nvidia-smi -L` lists. Read without initialising jax (its GPU allocation would starve the
    workers)."""
    visible = os.environ.get("CUDA_VISIBLE_DEVICES")
    if visible is not None:
        return list(dict.fromkeys(d.strip() for d in visible.split(",") if d.strip()))
    try:
        out = subprocess.run(["nvidia-smi", "-L"], capture_output=True, text=True, timeout=30).stdout
    except (OSError, subprocess.SubprocessError):
        return []
    return [str(i) for i in range(sum(line.startswith("GPU ") for line in out.splitlines()))]


def use_compilation_cache(path: str | None) -> str | None:
    """Turns on JAX's persistent compilation cache in `path` for this process (the `--parallel` driver passes the
    same setting to its workers): the parts of a run, its seeds and its resumes compile one program, so every
    start after the first on a machine loads it instead of compiling it again. None: the folder
    JAX_COMPILATION_CACHE_DIR names, else `.jax_cache/` in the repository; "off": no cache. Returns the folder
    used (None when off)."""
    import jax

    if path is None:
        path = os.environ.get("JAX_COMPILATION_CACHE_DIR") or os.path.join(ROOT, ".jax_cache")
    folder = None if path == "off" else path
    jax.config.update("jax_compilation_cache_dir", folder)
    return folder


def keep_off_the_gpus() -> None:
    """Puts this process's jax (the planning builds configs) on the CPU before it starts a backend: on a GPU it
    would take most of the first GPU's memory from the worker training there. Workers keep the environment's
    platforms (their environment is os.environ's)."""
    import jax

    jax.config.update("jax_platforms", "cpu")


def worker_command(key: str, gpu: str, seconds: float | None, runs_dir: str, reserve: float,
                   max_seeds: int | None = None, out: str = OUT_DIR, whole_parts: bool = False,
                   only_part: str | None = None, workers_per_gpu: int = 1,
                   compilation_cache: str | None = None) -> tuple[dict, list[str]]:
    """(environment, argv) of the process that trains run `key` (its part `only_part`, or all it has left) on GPU
    `gpu` within `seconds`; with several workers per GPU, each may take 90 % of the GPU's memory divided among
    them (XLA's preallocation would otherwise give the first one 75 %). `compilation_cache`: the driver's
    (a folder or "off"; None: the worker's default)."""
    argv = [sys.executable, "-m", "tools.experiments", "run", key, "--no-build", "--runs-dir", runs_dir,
            "--out", out, "--reserve", f"{reserve:g}"]
    if seconds is not None:
        argv += ["--time-limit", f"{int(seconds)}"]
    if max_seeds is not None:
        argv += ["--max-seeds", str(max_seeds)]
    if whole_parts:
        argv += ["--whole-parts"]
    if only_part is not None:
        argv += ["--only-part", only_part]
    if compilation_cache is not None:
        argv += ["--compilation-cache", compilation_cache]
    env = {**os.environ, "CUDA_VISIBLE_DEVICES": gpu}
    if workers_per_gpu > 1:
        env["XLA_PYTHON_CLIENT_MEM_FRACTION"] = f"{0.9 / workers_per_gpu:.3f}"
    return env, argv


def parallel_items(selection, runs_dir: str, max_seeds: int | None = None, out: str = OUT_DIR,
                   registry: dict | None = None, round_robin: bool = False) -> list[tuple[str, str]]:
    """(run key, part name) for each part a worker can take on its own: the done parts with cross-evaluations
    left where their checkpoints are, then the parts still to train (`pending_parts`, at most `max_seeds` seeds
    each), run after run. `round_robin`: the parts with a checkpoint first (a machine that goes back loses
    them), then the new parts by how many seeds their run has before them (done, started, or in its earlier new
    parts), so that a time-limited call screening several runs gets a seed of each before a second seed of any.
    Runs that share a folder are planned once (`planners`), so no part is listed twice."""
    plans = planners(selection, runs_dir, out, registry)
    crosses = [(st.key, part.name) for exp, st in plans
               for _, _, part, _ in folder_crosses(exp, st, runs_dir, out, registry)]
    pending = [(st, pending_parts(st, max_seeds)) for _, st in plans if st.status != "done"]
    if round_robin:
        started = [(st.key, part.name) for st, parts in pending for part in parts if part.steps]
        fresh = []  # (rank, run order, item): a new part ranks by the seeds its run has before it
        for order, (st, parts) in enumerate(pending):
            held = sum(p.count for p in st.done_parts) + sum(p.count for p in parts if p.steps)
            for part in (p for p in parts if not p.steps):
                fresh.append((held, order, (st.key, part.name)))
                held += part.count
        training = started + [item for *_, item in sorted(fresh)]
    else:
        training = [(st.key, part.name) for st, parts in pending for part in parts]
    return list(dict.fromkeys(crosses + training))


CARRY_RESERVE = (30.0, 15.0)
"""Seconds `run --carry-out` keeps from its time limit for packing the unfinished parts: a start, plus one
learner-only save per part that may be unfinished (one per worker slot)."""

WORKER_GRACE = (10.0, 60.0)
"""Seconds past the `--parallel` driver's deadline after which a worker still running is sent SIGINT (it saves a
checkpoint and exits; an evaluation under way finishes first), then killed: a time-limited call returns at most
about a minute late, so the command that started it still gets to copy its results."""


def train_parallel(selection, runs_dir: str, gpus: list[str], deadline: float | None, reserve: float, log=print,
                   max_seeds: int | None = None, out: str = OUT_DIR, whole_parts: bool = False,
                   worker_logs: str | None = None, workers_per_gpu: int = 1,
                   compilation_cache: str | None = None, round_robin: bool = False) -> bool:
    """Trains the parts not done (and evaluates done parts with cross-evaluations left where their checkpoints
    are) one per GPU side by side (a subprocess each, CUDA_VISIBLE_DEVICES=gpu, `--only-part`); a GPU that
    finishes takes the next part. A run's parts (its seeds, at most `max_seeds` a part) spread over the GPUs, so
    `--max-seeds 1` trains up to one seed per GPU. `worker_logs`: a folder where each worker writes its output
    (`<experiment>_<run>_<part>.log`, appended) instead of this process's stdout, where they would interleave.
    `workers_per_gpu`: workers sharing each GPU, for programs too small to fill one (the paper's SAC: 128 envs,
    batch 256), each GPU's first worker before any second one. `compilation_cache`: the folder the workers share
    (None: none). `round_robin`: the parts' order of `parallel_items`. Returns True when every run is done."""
    queue = parallel_items(selection, runs_dir, max_seeds, out, round_robin=round_robin)
    running: dict[tuple[int, str], tuple[subprocess.Popen, str]] = {}
    slots = [(k, gpu) for k in range(workers_per_gpu) for gpu in gpus]

    def name(slot: tuple[int, str]) -> str:
        return f"GPU {slot[1]}" + (f" worker {slot[0]}" if workers_per_gpu > 1 else "")

    if worker_logs is not None:
        os.makedirs(worker_logs, exist_ok=True)

    def refusal(key: str, part_name: str, seconds: float) -> str | None:
        """Why the worker of a part to train would not start with `seconds` left (`start_verdict`, as the
        worker decides it, without this call's start-ups), else None (also for a cross-evaluation item)."""
        for _, st in planners(selection, runs_dir, out):
            if st.key == key:
                for part in pending_parts(st, max_seeds):
                    if part.name == part_name:
                        verdict, why = start_verdict(st, part, seconds - reserve, False, None, whole_parts,
                                                     runs_dir, out)
                        return None if verdict == "start" else why
        return None

    interrupted, killed = set(), set()  # slots whose worker overran the deadline (no new worker starts by then)
    while queue or running:
        for slot in [s for s in slots if s not in running]:
            seconds = None if deadline is None else deadline - time.monotonic()
            while queue and seconds is not None:
                why = refusal(*queue[0], seconds)
                if why is None:
                    break
                key, part = queue.pop(0)
                log(f"{name(slot)}: {key} {part} not started: {why}")
            if not queue or (seconds is not None and seconds <= reserve):
                break
            key, part = queue.pop(0)
            env, argv = worker_command(key, slot[1], seconds, runs_dir, reserve, max_seeds, out, whole_parts, part,
                                       workers_per_gpu, compilation_cache or "off")
            path = None if worker_logs is None else os.path.join(worker_logs, f"{key.replace('/', '_')}_{part}.log")
            log(f"{name(slot)}: {key} {part}" + (f" (output: {path})" if path else ""))
            with contextlib.ExitStack() as stack:  # the worker keeps its own copy of the log file's handle
                output = {} if path is None else dict(stdout=stack.enter_context(open(path, "a")), stderr=subprocess.STDOUT)
                running[slot] = (subprocess.Popen(argv, env=env, cwd=ROOT, **output), f"{key} {part}")
        for slot, (proc, what) in list(running.items()):
            if proc.poll() is not None:
                log(f"{name(slot)}: {what} exited with status {proc.returncode}")
                del running[slot]
        if deadline is not None and time.monotonic() > deadline - reserve:
            queue.clear()
        if deadline is not None:
            late = time.monotonic() - deadline
            for slot, (proc, what) in running.items():
                if late > WORKER_GRACE[1] and slot not in killed:
                    log(f"{name(slot)}: {what} still running {late:.0f} s past the time limit: killed")
                    proc.kill()
                    killed.add(slot)
                elif late > WORKER_GRACE[0] and slot not in interrupted:
                    log(f"{name(slot)}: {what} still running {late:.0f} s past the time limit: interrupted (SIGINT)")
                    proc.send_signal(signal.SIGINT)
                    interrupted.add(slot)
        time.sleep(2)
    return all(run_state(exp, r, runs_dir, out).status == "done" for exp, runs in selection for r in runs)


# ------------------------------------------------------------------------------------------------
# Tables and figures.


def fmt_metric(metric: str, values) -> str:
    """'95.7 ± 0.4 %' for rates, '0.005 ± 0.001' for others (std over seeds; one seed: mean only)."""
    from agents.evaluation import COLUMNS, EXTRA_COLUMNS

    digits = {name: d for name, _, d in COLUMNS + EXTRA_COLUMNS}.get(metric, 3)
    values = [float(v) for v in ([values] if isinstance(values, (int, float)) else values)]
    mean = sum(values) / len(values)
    std = statistics.pstdev(values) if len(values) > 1 else None
    if metric in RATE_METRICS:
        return f"{100 * mean:.1f}" + (f" ± {100 * std:.1f}" if std is not None else "") + " %"
    return f"{mean:.{digits}f}" + (f" ± {std:.{digits}f}" if std is not None else "")


def header(metric: str) -> str:
    from agents.evaluation import COLUMNS, EXTRA_COLUMNS

    return TIMING_COLUMNS.get(metric) or {name: h for name, h, _ in COLUMNS + EXTRA_COLUMNS}.get(metric, metric)


def describe_overrides(run: Run) -> str:
    """'algo.q_hidden_sizes=512x512, env.observation=joint_pos+ee_pos, num_timesteps=100M': sizes joined by x,
    names by +; the budget where the run sets one other than its preset's."""
    def value(v) -> str:
        if isinstance(v, (tuple, list)):
            return ("+" if all(isinstance(x, str) for x in v) else "x").join(map(str, v))
        return str(v)

    parts = [f"{k}={value(v)}" for k, v in run.overrides.items()]
    if run.budget() != run.preset_budget():
        parts.append(f"num_timesteps={millions(run.num_timesteps)}")
    return ", ".join(parts)


def merged_evaluation(state: RunState, files: dict[str, str] | None = None) -> dict:
    """The done parts' eval.json (or the given files: {part name: path}, for the parts they name) merged:
    {"env_steps" (the fewest), "eval_envs", "seeds", "per_seed": {metric: [value per seed, by seed]}}."""
    merged: dict = {"per_seed": {}, "seeds": 0}
    parts = [p for p in state.done_parts if files is None or p.name in files]
    for part in parts:
        path = files[part.name] if files is not None else os.path.join(part.logdir, "eval.json")
        with open(path) as f:
            ev = json.load(f)
        keep = state.run_seeds(part)  # a shared part's seeds beyond this run's are left out
        merged["env_steps"] = min(merged.get("env_steps", ev["env_steps"]), ev["env_steps"])
        merged["eval_envs"] = ev["eval_envs"]
        merged["seeds"] += keep
        if ev.get("device"):  # eval.json files written before the device was recorded lack it
            merged.setdefault("devices", []).extend([ev["device"]] * keep)  # one per seed
        if ev.get("source"):  # a part recorded by tools.adopt_run: the evaluation it was made from
            merged.setdefault("sources", []).append(ev["source"]["eval_json"])
        for name, values in ev["per_seed"].items():
            merged["per_seed"].setdefault(name, []).extend(values[:keep])
    return merged


def cross_files(state: RunState, cross: Cross, record: str | None) -> dict[str, str]:
    """{part name: its cross-<name>.json} for the done parts that have one (of a done or a partial run). Fewer
    than the done parts: the others were not evaluated where their checkpoints were."""
    record_dir = record_folder(record, *state.owner) if record else None
    paths = {part.name: cross_path(part, cross, record_dir) for part in state.done_parts}
    return {name: path for name, path in paths.items() if path is not None}


def timing_cell(state: RunState, metric: str) -> str:
    """Wall-clock of one training process (mean over the parts) or env steps/s per seed; parts of different
    seed counts get one speed each ("500,000 (2 seeds) / 800,000 (1 seed)")."""
    parts = state.done_parts
    if metric == "wall_clock":
        return f"{state.wall_seconds:,.0f}" if state.wall_seconds > 0 else ""
    by_count: dict[int, list[float]] = {}
    for p in parts:
        if p.rate is not None:
            by_count.setdefault(p.count, []).append(p.rate)
    if len(by_count) == 1:
        return f"{statistics.mean(next(iter(by_count.values()))):,.0f}"
    return " / ".join(f"{statistics.mean(r):,.0f} ({n} seed{'s' if n > 1 else ''})" for n, r in sorted(by_count.items()))


def build_default(experiment: Experiment, states: list[RunState], out_dir: str, code: str | None = None) -> list[str]:
    """table.md and table.json (one row per run: the paper's numbers beside ours, mean ± std over seeds of
    the driver's evaluation) and curves.png (training curves from metrics.csv) in `out_dir`."""
    from agents.evaluation import code_version

    code = code or code_version()  # before anything is written (a written file would mark the tree modified)
    rows, table = [], []
    metrics, keys = list(experiment.metrics), table_metrics()

    def add(cells: list, row: dict, paper: dict, ev: dict | None, st: RunState, planned: int, timing: bool = True) -> None:
        """The metric cells (the paper's beside ours) of one row; `ev` None: not done; timing: the run's training
        wall-clock and speed in the timing columns."""
        if ev is not None:
            row.update(env_steps=ev["env_steps"], eval_envs=ev["eval_envs"], seeds_evaluated=ev["seeds"],
                       per_seed={}, mean={})
        for m in metrics:
            if m in TIMING_COLUMNS:
                cells += ["", timing_cell(st, m) if ev is not None and timing else ""]
                continue
            values = ev["per_seed"].get(keys[m]) if ev is not None else None
            if values is not None and len(values) != ev["seeds"]:  # a metric some parts' evaluations lack
                values = None
            cells += [fmt_metric(m, paper[m]) if m in paper else "", fmt_metric(m, values) if values is not None else ""]
            if values is not None:
                row["per_seed"][m] = values
                row["mean"][m] = sum(values) / len(values)
        if ev is None:
            cells[-1] = f"not done ({row['status']})"
        seeds = f"{ev['seeds']} x {ev['eval_envs']}" if ev is not None else f"{planned} x -"
        cells.append(seeds + (f" ({planned} planned)" if ev is not None and ev["seeds"] < planned else ""))
        devices = ev.get("devices", []) if ev is not None and timing else []
        cells.append(", ".join(f"{d} ({n} of {ev['seeds']})" if n < ev["seeds"] else d
                               for d, n in collections.Counter(devices).items()))
        if devices:
            row["devices"] = devices
        rows.append(cells)
        table.append(row)

    adopted = []  # runs trained by train.py before their experiment existed (tools.adopt_run)
    for st in states:
        run = st.run
        row = {"run": run.name, "label": run.title, "preset": run.preset, "overrides": run.overrides,
               "seeds": run.seeds, "num_timesteps": st.budget, "status": st.status, "folder": st.folder,
               "shared": st.shared, "paper": run.paper}
        if st.done_parts:  # a partial run's row holds its done seeds (the seeds x episodes column says how many)
            row.update(wall_seconds=st.wall_seconds, steps_per_second=st.rate,
                       parts=[{"seeds": p.name, "env_steps": p.steps, "wall_seconds": p.wall_seconds,
                               "steps_per_second_per_seed": p.rate} for p in st.done_parts])
        overrides = describe_overrides(run)
        cells = [run.title, f"`{run.preset}`" + (f" {overrides}" if overrides else "")]
        evaluated = merged_evaluation(st) if st.done_parts else None
        if evaluated and evaluated.get("sources"):
            row["sources"] = evaluated["sources"]
            adopted.append(f"{run.name} from {', '.join(evaluated['sources'])}")
        add(cells, row, run.paper, evaluated, st, run.seeds)
    by_name = {st.run.name: st for st in states}
    for cross in experiment.cross:
        st = by_name[cross.run]
        files = cross_files(st, cross, os.path.dirname(out_dir))
        label = cross.label or f"{st.run.title} on {cross.name}"
        status = ("not evaluated" if not files and st.done_parts else st.status if not files else
                  "done" if st.status == "done" and len(files) == len(st.done_parts) else "partly evaluated")
        row = {"run": cross.run, "cross": cross.name, "label": label, "env": cross.env, "paper": cross.paper,
               "stochastic": cross.stochastic, "seeds": st.run.seeds, "status": status}
        cells = [label, f"`{cross.run}`'s policies, evaluated with {cross.setting}"]
        add(cells, row, cross.paper, merged_evaluation(st, files) if files else None, st, st.run.seeds, timing=False)
    head = (["run", "preset and overrides"] + [h for m in metrics for h in (f"paper: {header(m)}", header(m))]
            + ["seeds x episodes", "device (training's last call)"])
    keep = [i for i in range(len(head)) if not head[i].startswith(("paper: ", "device")) or any(r[i] for r in rows)]
    lines = [f"# {experiment.title}", "", f"Paper: {experiment.paper_ref}." + (f" {experiment.paper}" if experiment.paper else ""), ""]
    if experiment.note:
        lines += [experiment.note, ""]
    lines += ["| " + " | ".join(head[i] for i in keep) + " |", "|" + "---|" * len(keep)]
    lines += ["| " + " | ".join(r[i] for i in keep) + " |" for r in rows]
    budget = ", ".join(f"{st.run.name} {st.run.seeds} x {millions(st.budget)}" for st in states)
    command = f"python -m tools.experiments run {experiment.name}"
    shared = [f"{st.run.name} trains in {st.shared}" for st in states if st.shared]
    lines += ["", "Ours: the deterministic policy's evaluation at the end of training (the runs' eval.json; "
              "a cross row: the setting its second column names), mean ± std over seeds; rates in %, "
              "distances in m. Each run's config.json, eval.json and metrics.csv per part (the "
              "seeds trained in one process): `runs/<run>/seeds-<first>-<last>/` beside this table"
              + (f" ({'; '.join(shared)}: the same training config, trained once)" if shared else "") + ".",
              f"Runs (seeds x env steps): {budget}.", f"Command: `{command}`."
              + (f" Trained by `train.py` before this experiment and recorded with `tools.adopt_run` from the "
                 f"`eval.py` evaluation of the final checkpoint: {'; '.join(adopted)}." if adopted else ""),
              f"Code {code}, built {datetime.date.today().isoformat()}.", ""]
    os.makedirs(out_dir, exist_ok=True)
    written = [os.path.join(out_dir, "table.md"), os.path.join(out_dir, "table.json")]
    with open(written[0], "w") as f:
        f.write("\n".join(lines))
    data = {"experiment": experiment.name, "title": experiment.title, "paper_ref": experiment.paper_ref,
            "paper": experiment.paper, "command": command, "code": code,
            "date": datetime.date.today().isoformat(), "rows": table}
    with open(written[1], "w") as f:
        json.dump(data, f, indent=2)
    figure = training_figure(experiment, states, os.path.join(out_dir, "curves.png"))
    return written + ([figure] if figure else [])


def training_figure(experiment: Experiment, states: list[RunState], path: str) -> str | None:
    """curves.png of the runs with a metrics.csv, a row per `curve_groups` row (else one), a panel per curve and
    axis (None without matplotlib, curves or logs)."""
    try:
        import matplotlib  # noqa: F401
    except ImportError:
        return None
    from tools import plots

    logged = {st.run.name: (st.run.title, [p.logdir for p in st.done_parts
                                           if os.path.isfile(os.path.join(p.logdir, "metrics.csv"))]) for st in states}
    rows = experiment.curve_groups or (("", tuple(logged)),)
    groups = {title: {logged[name][0]: logged[name][1] for name in names if name in logged and logged[name][1]}
              for title, names in rows}
    groups = {title: runs for title, runs in groups.items() if runs}
    if not experiment.curves or not groups:
        return None
    present = [m for m in experiment.curves
               if all(m in plots.read_metrics(d) for runs in groups.values() for ds in runs.values() for d in ds)]
    if not present:
        return None
    keep = {p.logdir: st.run_seeds(p) for st in states for p in st.done_parts}  # the seeds each table row averages
    fig = plots.curve_grid(groups, present, experiment.curve_axes, path, experiment.title, keep=keep)
    import matplotlib.pyplot as plt

    plt.close(fig)
    return path


RECORDED_FILES = ("config.json", "eval.json", "metrics.csv")
"""What a build copies of each finished part into the results, with its cross-*.json (checkpoints stay in the
runs folder)."""


def record_parts(state: RunState, record: str, only: str | None = None) -> list[str]:
    """Copies the files of the run's finished parts (or of the part named `only`) into the record folder of the
    run whose folder it trains in (`record_folder`), so that the results hold the evidence behind the table and
    the next checkout sees those parts done."""
    from agents.checkpoint import write_atomic

    written = []
    target_dir = record_folder(record, *state.owner)
    for part in state.done_parts:
        if only is not None and part.name != only:
            continue
        target = os.path.join(target_dir, part.name)
        if os.path.abspath(part.logdir) == os.path.abspath(target):
            continue
        os.makedirs(target, exist_ok=True)
        crosses = sorted(n for n in os.listdir(part.logdir) if n.startswith("cross-") and n.endswith(".json"))
        for name in RECORDED_FILES + tuple(crosses):
            if os.path.isfile(os.path.join(part.logdir, name)):
                with open(os.path.join(part.logdir, name)) as f:
                    write_atomic(os.path.join(target, name), f.read())  # readers see the old file or the new
                written.append(os.path.join(target, name))
    return written


def record(selection, runs_dir: str, out: str, registry: dict | None = None) -> list[str]:
    """Records the finished parts of every selected run (`record_parts`), built table or not: what a GPU call
    brings back is `out`. Each file once, though runs sharing a folder both record it."""
    return list(dict.fromkeys(path for exp, runs in selection for r in runs
                              for path in record_parts(run_state(exp, r, runs_dir, out, registry), out)))


def build(selection, runs_dir: str, out: str, complete_only: bool = False, log=print, registry: dict | None = None) -> list[str]:
    """Builds each selected experiment's table and figure into `<out>/<experiment>/`, after recording its runs'
    finished parts there (with `complete_only`, only experiments whose runs are all done); returns the files
    written."""
    from agents.evaluation import code_version

    written, code = [], code_version()  # once: the first table written would mark the tree modified
    for exp, _ in selection:
        states = [run_state(exp, r, runs_dir, out, registry) for r in exp.runs]
        if not any(st.done_parts for st in states) or (complete_only and any(st.status != "done" for st in states)):
            continue
        files = [f for st in states for f in record_parts(st, out)]
        states = [run_state(exp, r, runs_dir, out, registry) for r in exp.runs]
        builder = exp.builder or functools.partial(build_default, code=code)
        files += builder(exp, states, os.path.join(out, exp.name))
        for path in files:
            log(f"wrote {path}")
        written += files
    return written


# ------------------------------------------------------------------------------------------------
# Command line.


ACTION_FLAGS = {"time-limit": ("run",), "reserve": ("run",), "parallel": ("run",), "no-build": ("run",),
                "carry-in": ("run",), "carry-out": ("run",), "carry-max-mb": ("run",),
                "whole-parts": ("run",), "compilation-cache": ("run",), "all": ("commands",),
                "max-seeds": ("run", "commands", "list")}
"""Options that mean something only to some actions (those --parallel needs are checked with it)."""


def main(argv=None) -> int:
    p = argparse.ArgumentParser(prog="python -m tools.experiments", description=__doc__.split("\n\n")[0])
    p.add_argument("action", choices=("list", "run", "commands", "build", "record"))
    p.add_argument("names", nargs="*", help="experiments or experiment/run (default: all)")
    p.add_argument("--runs-dir", default=RUNS_DIR, help=f"where runs are trained (default {RUNS_DIR})")
    p.add_argument("--out", default=OUT_DIR, help=f"where tables and figures go (default {OUT_DIR})")
    p.add_argument("--time-limit", type=float, help="run: return within this many seconds of the start")
    p.add_argument("--reserve", type=float, help="run: seconds kept for the last checkpoint, evaluation and exit "
                                                  "(default: 10 %% of --time-limit, at least 30)")
    p.add_argument("--parallel", action="store_true", help="run: one part per local GPU, side by side (subprocesses)")
    p.add_argument("--worker-logs", help="run --parallel: a folder for each worker's output (one file per part) "
                   "instead of this process's stdout")
    p.add_argument("--gpus", type=int, help="run --parallel: the first N of the GPUs CUDA_VISIBLE_DEVICES names, "
                                            "else of those nvidia-smi lists (default: all of them)")
    p.add_argument("--workers-per-gpu", type=int, default=1, help="run --parallel: workers sharing each GPU "
                   "(default 1), for runs too small to fill a GPU (the paper's SAC); each may use 90 %% of its "
                   "memory divided among them")
    p.add_argument("--round-robin", action="store_true", help="run --parallel (one GPU too): the parts with a "
                   "checkpoint first, then the new parts ranked by how many seeds their run has before them, done, "
                   "started or new (a seed of each row first, with --max-seeds 1), instead of run after run")
    p.add_argument("--no-build", action="store_true", help="run: no tables (finished parts are still recorded, each "
                   "as it finishes)")
    p.add_argument("--all", action="store_true", help="commands: also the runs done (each as a fresh run)")
    p.add_argument("--max-seeds", type=int, help="run, commands, list: seeds trained together in one train.py "
                                                 "process (default: all of a run's; 1 trains each seed on its own); "
                                                 "list plans its GPU time so")
    p.add_argument("--only-part", help="run: train only this part (seeds-<first>-<last>, as --max-seeds plans them "
                   "and `commands` names them) of the one run named, and its cross-evaluations: what --parallel's "
                   "workers do")
    p.add_argument("--compilation-cache", default=None, metavar="DIR",
                   help="run: JAX's persistent compilation cache, shared by the parts and their resumes (default: "
                   "$JAX_COMPILATION_CACHE_DIR, else .jax_cache/ in the repository; 'off' for none)")
    p.add_argument("--carry-in", metavar="DIR", help="run: first put the parts packed in DIR (by --carry-out on "
                   "another machine) into --runs-dir (`tools.carry_parts unpack`)")
    p.add_argument("--carry-out", metavar="DIR", help="run: last, pack the unfinished parts of the named runs "
                   "learner-only into DIR (`tools.carry_parts pack`), for a machine that will not keep its runs/; with "
                   "--time-limit, training stops early enough for it")
    p.add_argument("--carry-max-mb", type=float, help="run --carry-out: each bundle's total in MiB, what one call "
                   "carries (default: `tools.carry_parts.TOTAL_MB`; first fit, the parts with the most steps first, "
                   "into DIR, DIR/more-1, ...)")
    p.add_argument("--whole-parts", action="store_true", help="run --time-limit: train only the parts predicted to "
                   "finish in time (measured speeds; for a config never timed, its preset's), for a last call on a "
                   "machine that will not keep its runs/")
    args = p.parse_args(argv)
    if args.max_seeds is not None and args.max_seeds < 1:
        raise ValueError(f"--max-seeds={args.max_seeds} is impossible: allowed is 1 or more (or leave it out).")
    lone = [flag for flag, given in (("worker-logs", args.worker_logs is not None), ("gpus", args.gpus is not None),
                                     ("workers-per-gpu", args.workers_per_gpu != 1),
                                     ("round-robin", args.round_robin)) if given]
    if lone and not args.parallel:
        raise ValueError(f"--{lone[0]} without --parallel is meaningless: allowed is `run --parallel` with it.")
    if args.workers_per_gpu < 1:
        raise ValueError(f"--workers-per-gpu={args.workers_per_gpu} is impossible: allowed is 1 or more.")
    if args.gpus is not None and args.gpus < 1:
        raise ValueError(f"--gpus={args.gpus} is impossible: allowed is 1 or more (or leave it out).")
    for flag, actions in ACTION_FLAGS.items():
        given = getattr(args, flag.replace("-", "_"))
        if given is not None and given is not False and args.action not in actions:
            raise ValueError(f"--{flag} with {args.action} is meaningless: allowed is "
                             f"{' or '.join(f'`{a}`' for a in actions)} with it.")
    if args.whole_parts and args.time_limit is None:
        raise ValueError("--whole-parts without --time-limit is meaningless: allowed is --whole-parts with "
                         "--time-limit S (every part fits no limit).")
    start = time.monotonic()
    selection = select(args.names)
    if args.only_part is not None:
        runs = [r for _, rs in selection for r in rs]
        if args.action != "run" or args.parallel or len(runs) != 1:
            raise ValueError(f"--only-part={args.only_part!r} needs `run` of exactly one run (experiment/run) without "
                             f"--parallel: given {args.action} of {len(runs)} runs" + (" with --parallel" if args.parallel else ""))
        parsed = parse_part(args.only_part)
        if parsed is None or part_name(*parsed) != args.only_part:
            raise ValueError(f"--only-part={args.only_part!r} is not a part name: allowed is seeds-<first>-<last> "
                             "(first <= last, no leading zeros), as the logdirs of `commands` name them.")
    if args.action == "list":
        print(listing(selection, args.runs_dir, args.out, max_seeds=args.max_seeds))
    elif args.action == "commands":
        print("\n".join(commands(selection, args.runs_dir, args.all, args.max_seeds, args.out)))
    elif args.action == "build":
        build(selection, args.runs_dir, args.out)
    elif args.action == "record":
        written = record(selection, args.runs_dir, args.out)
        print("\n".join([f"recorded {path}" for path in written]
                        + [f"{len(written)} files recorded from {args.runs_dir} into {args.out}"]))
    else:
        from tools import carry_parts

        if args.carry_max_mb is not None and args.carry_out is None:
            raise ValueError("--carry-max-mb without --carry-out is meaningless: allowed is --carry-max-mb with "
                             "--carry-out DIR.")
        if args.carry_max_mb is not None and not args.carry_max_mb > 0:
            raise ValueError(f"--carry-max-mb={args.carry_max_mb} is invalid: allowed is a number > 0.")
        if args.carry_in is not None and not os.path.isdir(args.carry_in):
            raise ValueError(f"--carry-in={args.carry_in!r} is not a folder: allowed is a folder that --carry-out "
                             "(or `tools.carry_parts pack --to`) wrote.")
        cache = use_compilation_cache(args.compilation_cache)
        reserve = args.reserve if args.reserve is not None else (max(30.0, 0.1 * args.time_limit) if args.time_limit else 0.0)
        gpus = []
        if args.parallel:
            keep_off_the_gpus()
            visible = local_gpus()
            gpus = visible if args.gpus is None else (visible or [str(i) for i in range(args.gpus)])[:args.gpus]
            if not gpus:
                raise ValueError("--parallel found no GPU: allowed is a host with GPUs (or --gpus N).")
        packing = CARRY_RESERVE[0] + CARRY_RESERVE[1] * max(1, len(gpus) * args.workers_per_gpu) if args.carry_out else 0.0
        deadline = None if args.time_limit is None else start + args.time_limit - packing
        if args.carry_in is not None:
            if carry_parts.has_pieces(args.carry_in):
                carry_parts.unpack(args.carry_in, args.runs_dir)
            else:
                print(f"--carry-in: no pieces in {args.carry_in}")
        if args.parallel:
            finished = train_parallel(selection, args.runs_dir, gpus, deadline, reserve,
                                      max_seeds=args.max_seeds, out=args.out, whole_parts=args.whole_parts,
                                      worker_logs=args.worker_logs, workers_per_gpu=args.workers_per_gpu,
                                      compilation_cache=cache, round_robin=args.round_robin)
        else:
            finished = train_pending(selection, args.runs_dir, deadline, reserve, max_seeds=args.max_seeds,
                                     record=args.out, whole_parts=args.whole_parts, record_each=True,
                                     only_part=args.only_part)
        if args.carry_out is not None:
            # Only this command's runs: another command may be training other runs in the same folder.
            carry_parts.pack(args.runs_dir, args.carry_out, runs=run_folders(selection),
                             max_total_mb=carry_parts.TOTAL_MB if args.carry_max_mb is None else args.carry_max_mb)
        if not args.no_build:
            for path in record(selection, args.runs_dir, args.out):
                print(f"recorded {path}")
            build(selection, args.runs_dir, args.out, complete_only=True)
        if not finished:
            print("not finished: `python -m tools.experiments run` again continues.")
    return 0


if __name__ == "__main__":
    from tools import run_cli

    run_cli(main)
