"""The state of a registered experiment's runs, read from their folders: a run trains in parts,
`<runs-dir>/<experiment>/<run>/seeds-<first>-<last>/` (a train.py logdir each, the seeds trained together in one
process), and each part is missing (nothing), partial (some progress), trained (at the budget, not evaluated),
done (its `eval.json` written at the end of training) or changed (its `config.json` differs from the registry's run
in a field a resume may not change). Runs of different experiments with equal training configs share the folder of
the first one registered and train once. The results' record of finished parts (`<out>/<experiment>/runs/<run>/`)
counts too, so a checkout without the runs folder knows what is done.

Also here: the validation of a registered experiment and its cross-evaluations (a run's final policies on another
env setting, or with sampled actions, into `cross-<name>.json` beside `eval.json`).
"""

from __future__ import annotations

import csv
import dataclasses
import json
import math
import os
import statistics

import envs
from agents import evaluation, provenance
from agents.checkpoint import write_atomic
from agents.config import config_json, merge_resume_config, read_config, validate
from agents.presets import PRESETS
from tools import experiment_registry  # noqa: F401  (registers the experiments in EXPERIMENTS)
from tools.experiment_spec import EXPERIMENTS, Cross, Experiment, Run

RUNS_DIR = os.path.join("runs", "experiments")
OUT_DIR = os.path.join("results", "experiments")
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
    return {**evaluation.PAPER_METRICS, **{name: evaluation.EXTRA_METRICS[name] for name, _, _ in evaluation.EXTRA_COLUMNS}}




def validate_experiment(experiment: Experiment) -> None:
    """Builds and validates every run's TrainConfig (agents.config.validate; nothing compiles)."""
    for run in experiment.runs:
        where = f"experiment {experiment.name!r}, run {run.name!r}"
        if run.preset not in PRESETS:
            raise ValueError(f"{where}: preset={run.preset!r} is unknown: allowed are {', '.join(sorted(PRESETS))}.")
        try:
            validate(run.config(logdir=os.path.join(RUNS_DIR, experiment.name, run.name)))
        except (ValueError, TypeError) as error:
            raise ValueError(f"{where}: {error}") from error
        unknown = [m for m in run.paper if m not in evaluation.PAPER_METRICS]
        if unknown:
            raise ValueError(f"{where}: paper metric {unknown[0]!r} is unknown: allowed are {', '.join(evaluation.PAPER_METRICS)}.")
    for cross in experiment.cross:
        where = f"experiment {experiment.name!r}, cross {cross.name!r}"
        run = experiment.run(cross.run)
        if not cross.name or any(not (c.isalnum() or c in "-_.") for c in cross.name):
            raise ValueError(f"{where}: name={cross.name!r} is invalid: allowed are letters, digits, '-', '_' and '.'.")
        if not cross.env and not cross.stochastic:
            raise ValueError(f"{where}: env={{}} with stochastic=False evaluates the run as trained again: allowed are "
                             "env fields to change, stochastic=True, or both.")
        unseen = evaluation.unseen_constants(run.config().env, cross_env(run, cross, where))
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
        without any (a part recorded from an earlier train.py run, its timings left out)."""
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


def read_timing(logdir: str, seeds: int) -> tuple[float | None, float]:
    """(env steps/s per seed, wall-clock seconds) from metrics.csv: one row per logged chunk (the seeds' rows
    share the speed; rows of no positive, finite speed are skipped); a resumed run's re-logged steps count once.
    The speed is the median over the chunks after the first (which holds the compilation; the first chunk of each
    later call, a resume, stays in: with many chunks a call it moves the median little): None with one chunk
    only. None, 0 without chunks."""
    path = os.path.join(logdir, "metrics.csv")
    if not os.path.isfile(path):
        return None, 0.0
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
        return None, 0.0
    steps = sorted(chunks)
    rate = statistics.median(chunks[s][0] / seeds for s in steps[1:]) if len(steps) > 1 else None
    return rate, sum(w for _, w in chunks.values())


def part_state(run: Run, logdir: str, first: int, count: int) -> PartState:
    """The state of seeds `first` .. `first + count - 1` of `run` from the files in `logdir`."""
    budget = run.budget()
    steps = (checkpoint_steps(logdir) or [0])[-1]
    rate, wall = read_timing(logdir, count)
    state = PartState(logdir, first, count, "missing", steps, budget, rate, wall)
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
        text = json.dumps(config_json(dataclasses.replace(run.config(), seeds=1)), sort_keys=True)
        cached = _RECIPES[id(run)] = (run, text)
    return cached[1]


def storage(experiment: Experiment, run: Run, registry: dict | None = None) -> tuple[str, str]:
    """(experiment, run) whose folder trains `run`: the first run of the registry with the same recipe (so an
    experiment's baseline that another experiment also has trains once), or the last such run before it that does
    not share (`Run.shares`: where the code changed the task under that recipe, runs from there on share its
    folder), else the run's own (always where the run does not share)."""
    registry = EXPERIMENTS if registry is None else registry
    if run.shares and registry.get(experiment.name) is experiment:
        key, owner = recipe(run), None
        for exp in registry.values():
            for other in exp.runs:
                if other is run:
                    return owner or (exp.name, other.name)
                if recipe(other) == key and (owner is None or not other.shares):
                    owner = exp.name, other.name
    return experiment.name, run.name


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
    config = run.config(part.logdir, first_seed=part.first, seeds=part.count)
    result = evaluation.run(evaluation.checkpoint_policy(part.logdir), config.env_name, cross_env(run, cross),
                            num_envs=config.eval_envs, eval_seeds=(config.eval_seed,), stochastic=cross.stochastic)
    path = os.path.join(part.logdir, f"cross-{cross.name}.json")
    write_atomic(path, json.dumps({"env_steps": part.steps, "eval_envs": config.eval_envs, "env": cross.env,
                                   "actions": "stochastic" if cross.stochastic else "deterministic",
                                   "provenance": provenance.stamp(), **driver_metrics(result.units)}, indent=2))
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


def millions(steps: float) -> str:
    return f"{steps / 1e6:g}M"


def table_built(experiment: Experiment, out: str) -> bool:
    return os.path.isfile(os.path.join(out, experiment.name, "table.json"))


# ------------------------------------------------------------------------------------------------
# list and commands.



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

