"""Algorithms compared over tasks the rliable way (Agarwal et al., "Deep RL at the Edge of the Statistical
Precipice", NeurIPS 2021): median, IQM, mean and optimality gap of one per-seed metric with 95 % stratified-bootstrap
confidence intervals, and the probability that one algorithm beats another on a task, averaged over the tasks.

Command line (the example under results/comparisons/ was made with this, on a CPU):

    python -m tools.compare_runs --metric target_reached --out results/comparisons/NAME \\
        --run PPO:ur5e-reach=runs/ur5e-reach-ppo --run SAC:ur5e-reach=runs/ur5e-reach-sac ...

Each `--run ALGO:TASK=PATH` adds the seeds of one training run: PATH is a train.py logdir (its eval.json), an
eval.json, or an experiment's run folder holding parts `seeds-<first>-<last>/eval.json` (all of them, by first
seed). The same ALGO:TASK given again adds that run's seeds after the earlier ones. Every algorithm needs every
task. rliable's score matrix is seeds x tasks, so an algorithm's tasks need the same number of seeds: unequal
counts are refused, or with `--truncate-seeds` cut to the fewest (each task's first seeds, with a warning).
Algorithms may differ in seeds. Scores are taken as they are: P(X > Y) is the chance that X's value is higher,
an improvement only for metrics where higher is better (target_reached, not the collisions or distances); the
optimality gap is the mean shortfall below `--gamma` (1: the rates' best).

Writes aggregate.png and improvement.png (rliable's figures), comparison.json (every number, the scores and
their files) and comparison.md (the tables) into --out.
"""

from __future__ import annotations

import argparse
import datetime
import glob
import json
import math
import os
import re
import warnings

import numpy as np
from rliable import library as rly
from rliable import metrics, plot_utils

from agents import intervals
from agents.provenance import code_version, command
from tools import plots, run_cli

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
METRIC_PREFIX = "episode/"
"""eval.json's per-seed keys start with this; --metric names them with or without it."""
AGGREGATES = ("median", "IQM", "mean", "optimality gap")
"""rliable's aggregate metrics, in its figure's order."""
PAIR_SEPARATOR = ","
"""Joins the two algorithms of a pair in rliable's probability-of-improvement dictionaries (not allowed in names)."""
REPS = 2000
"""Default bootstrap resamples per interval (rliable's guidance: at least 2,000 for a figure; a few seconds here)."""
RUN_PATTERN = re.compile(r"^([^:=,]+):([^:=,]+)=(.+)$")
"""ALGO:TASK=PATH of --run."""


# ------------------------------------------------------------------------------------------------
# Reading the runs


def parse_run(text: str) -> tuple[str, str, str]:
    """(algorithm, task, path) of one --run value ALGO:TASK=PATH."""
    match = RUN_PATTERN.match(text)
    if not match or not match.group(1).strip() or not match.group(2).strip():
        raise ValueError(f"--run {text!r} is malformed: allowed is ALGO:TASK=PATH (ALGO and TASK non-empty, "
                         "without ':', '=' or ',').")
    return match.group(1).strip(), match.group(2).strip(), match.group(3)


def eval_files(path: str) -> list[str]:
    """The eval.json files a PATH stands for: itself, the logdir's eval.json, or its parts' (by first seed)."""
    if os.path.isfile(path):
        return [path]
    if os.path.isfile(os.path.join(path, "eval.json")):
        return [os.path.join(path, "eval.json")]
    parts = glob.glob(os.path.join(glob.escape(path), "seeds-*-*", "eval.json"))
    first_seed = re.compile(r"seeds-(\d+)-(\d+)$")
    parts = [p for p in parts if first_seed.search(os.path.dirname(p))]
    if not parts:
        raise ValueError(f"{path!r} has no eval.json: allowed is an eval.json, a train.py logdir holding one, or a "
                         "run folder of parts seeds-<first>-<last>/eval.json.")
    return sorted(parts, key=lambda p: int(first_seed.search(os.path.dirname(p)).group(1)))


def metric_names(per_seed: dict) -> list[str]:
    """The --metric names an eval.json's per-seed results offer (their keys without the prefix)."""
    return sorted(k[len(METRIC_PREFIX):] if k.startswith(METRIC_PREFIX) else k for k in per_seed)


def read_seeds(path: str, metric: str) -> list[float]:
    """The per-seed values of `metric` in one eval.json (the training driver's: {"per_seed": {key: [value per
    seed]}, ...})."""
    try:
        with open(path) as f:
            per_seed = json.load(f)["per_seed"]
    except (OSError, json.JSONDecodeError, KeyError, TypeError) as error:
        raise ValueError(f"{path!r} is not a run's eval.json with per-seed results ({error}): allowed is the "
                         "eval.json train.py writes.") from None
    key = metric if metric in per_seed else METRIC_PREFIX + metric
    if key not in per_seed:
        raise ValueError(f"--metric {metric!r} is not in {path}: allowed are {', '.join(metric_names(per_seed))}.")
    values = [float(v) for v in per_seed[key]]
    if not values or not all(math.isfinite(v) for v in values):
        raise ValueError(f"{path}: {key} is {per_seed[key]!r}: allowed are finite values, one per seed.")
    return values


def collect(runs: list[tuple[str, str, str]], metric: str) -> tuple[dict, dict]:
    """({algorithm: {task: [value per seed]}}, {algorithm: {task: [eval.json paths]}}) in the order given."""
    scores: dict = {}
    sources: dict = {}
    seen: set = set()
    for algo, task, path in runs:
        for file in eval_files(path):
            real = os.path.realpath(file)
            if real in seen:
                raise ValueError(f"--run {algo}:{task}={path}: {file} is given twice: allowed is each run's seeds once.")
            seen.add(real)
            scores.setdefault(algo, {}).setdefault(task, []).extend(read_seeds(file, metric))
            sources.setdefault(algo, {}).setdefault(task, []).append(_shown(file))
    return scores, sources


def _shown(path: str) -> str:
    """A path as the outputs name it: relative to the repository where it lies inside it."""
    path = os.path.abspath(path)
    return os.path.relpath(path, ROOT) if path.startswith(ROOT + os.sep) else path


def score_matrices(scores: dict, truncate: bool = False) -> tuple[dict, list[str], dict]:
    """({algorithm: seeds x tasks array}, tasks, {algorithm: {task: seeds dropped}}): rliable's score matrices.
    An algorithm's tasks with unequal seed counts are refused, or cut to the fewest with `truncate`."""
    if len(scores) < 2:
        raise ValueError(f"--run names {len(scores)} algorithm(s) ({', '.join(scores)}): allowed are 2 or more.")
    tasks = list(dict.fromkeys(t for by_task in scores.values() for t in by_task))
    for algo, by_task in scores.items():
        missing = [t for t in tasks if t not in by_task]
        if missing:
            raise ValueError(f"algorithm {algo!r} has no run for task(s) {', '.join(missing)}: allowed is a --run "
                             "for every algorithm and task.")
    matrices, dropped = {}, {}
    for algo, by_task in scores.items():
        counts = {t: len(by_task[t]) for t in tasks}
        fewest = min(counts.values())
        if fewest != max(counts.values()):
            text = ", ".join(f"{t} {n}" for t, n in counts.items())
            if not truncate:
                raise ValueError(f"algorithm {algo!r} has unequal seeds per task ({text}): allowed is the same number "
                                 "on every task (--truncate-seeds keeps each task's first seeds, the fewest count).")
            warnings.warn(f"{algo}: seeds per task {text}; each task's first {fewest} kept.", stacklevel=2)
            dropped[algo] = {t: n - fewest for t, n in counts.items() if n > fewest}
        matrices[algo] = np.array([by_task[t][:fewest] for t in tasks], np.float64).T
    return matrices, tasks, dropped


# ------------------------------------------------------------------------------------------------
# rliable's estimates


def bootstrap(key: str, scores, func, reps: int, seed: int) -> tuple[np.ndarray, np.ndarray]:
    """(point estimate, [low, high] per value) of `func` on one algorithm's matrix (or a pair's list of two) by
    rliable's stratified bootstrap, seeded for this key alone: an algorithm's interval does not depend on which
    others are compared."""

    with intervals.seeded_numpy(seed):
        points, cis = rly.get_interval_estimates({key: scores}, func, reps=reps,
                                                 confidence_interval_size=intervals.CONFIDENCE)
    return np.atleast_1d(np.asarray(points[key], np.float64)), np.asarray(cis[key], np.float64).reshape(2, -1)


def aggregate_estimates(matrices: dict, reps: int, seed: int, gamma: float = 1.0) -> dict:
    """{algorithm: {aggregate: {"estimate", "ci"}}}: rliable's median, IQM, mean and optimality gap over seeds x
    tasks with their confidence intervals."""

    def func(s):
        return np.array([metrics.aggregate_median(s), metrics.aggregate_iqm(s), metrics.aggregate_mean(s),
                         metrics.aggregate_optimality_gap(s, gamma)])

    result = {}
    for algo, matrix in matrices.items():
        points, cis = bootstrap(algo, matrix, func, reps, seed)
        result[algo] = {name: {"estimate": float(points[i]), "ci": [float(cis[0, i]), float(cis[1, i])]}
                        for i, name in enumerate(AGGREGATES)}
    return result


def improvement_estimates(matrices: dict, reps: int, seed: int) -> list[dict]:
    """[{"x", "y", "estimate", "ci"}] for each pair of algorithms (X listed before Y): P(X > Y), the probability that
    X's seed beats Y's on a task (ties count half), averaged over tasks, with its confidence interval."""

    algos = list(matrices)
    result = []
    for i, x in enumerate(algos):
        for y in algos[i + 1:]:
            points, cis = bootstrap(x + PAIR_SEPARATOR + y, [matrices[x], matrices[y]],
                                    metrics.probability_of_improvement, reps, seed)
            result.append({"x": x, "y": y, "estimate": float(points[0]), "ci": [float(cis[0, 0]), float(cis[1, 0])]})
    return result


# ------------------------------------------------------------------------------------------------
# Figures and tables


def plot_aggregate(aggregate: dict, metric: str, path: str) -> str:
    """aggregate.png: rliable's interval-estimates figure, a panel per aggregate, a bar per algorithm."""

    plt = plots.pyplot()
    points = {a: np.array([v[n]["estimate"] for n in AGGREGATES]) for a, v in aggregate.items()}
    cis = {a: np.array([[v[n]["ci"][0] for n in AGGREGATES], [v[n]["ci"][1] for n in AGGREGATES]])
           for a, v in aggregate.items()}
    fig, _ = plot_utils.plot_interval_estimates(points, cis, metric_names=list(AGGREGATES),
                                                algorithms=list(aggregate), xlabel=metric, max_ticks=3,
                                                subfigure_width=4.0, row_height=max(0.37, 1.6 / len(aggregate)),
                                                xlabel_y_coordinate=-0.25)
    fig.savefig(path, dpi=110, bbox_inches="tight")
    plt.close(fig)
    return path


def plot_improvement(improvement: list[dict], metric: str, path: str) -> str:
    """improvement.png: rliable's probability-of-improvement figure, a bar per pair (X left, Y right)."""

    plt = plots.pyplot()
    probs = {p["x"] + PAIR_SEPARATOR + p["y"]: p["estimate"] for p in improvement}
    cis = {p["x"] + PAIR_SEPARATOR + p["y"]: np.array(p["ci"]) for p in improvement}
    ax = plot_utils.plot_probability_of_improvement(probs, cis, pair_separator=PAIR_SEPARATOR,
                                                    figsize=(4.5, 1.2 + 0.6 * len(improvement)),
                                                    xticks=[0.0, 0.25, 0.5, 0.75, 1.0], xlabel=f"P(X > Y), {metric}")
    ax.figure.savefig(path, dpi=110, bbox_inches="tight")
    plt.close(ax.figure)
    return path


def _cell(stats: dict, digits: int = 3) -> str:
    """'0.962 [0.955, 0.968]': an estimate and its interval."""
    low, high = stats["ci"]
    return f"{stats['estimate']:.{digits}f} [{low:.{digits}f}, {high:.{digits}f}]"


def markdown(report: dict) -> str:
    """comparison.md: the per-task means, the aggregates and P(X > Y), with how they were made."""
    algos, tasks = list(report["aggregate"]), report["tasks"]
    lines = [f"# {' vs '.join(algos)}: {report['metric']} over {len(tasks)} tasks", "",
             "Per task: the mean over seeds (seeds in brackets).", "",
             "| algorithm | " + " | ".join(tasks) + " |", "|---|" + "---|" * len(tasks)]
    for a in algos:
        cells = [f"{np.mean(report['scores'][a][t]):.3f} ({len(report['scores'][a][t])})" for t in tasks]
        lines.append(f"| {a} | " + " | ".join(cells) + " |")
    lines += ["", "Aggregates over seeds x tasks, in brackets the 95 % stratified-bootstrap confidence interval "
              f"(rliable, {report['reps']} resamples, seed {report['seed']}; optimality gap below {report['gamma']:g}).",
              "", "| algorithm | " + " | ".join(AGGREGATES) + " |", "|---|" + "---|" * len(AGGREGATES)]
    for a in algos:
        lines.append(f"| {a} | " + " | ".join(_cell(report["aggregate"][a][n]) for n in AGGREGATES) + " |")
    lines += ["", "Probability of improvement: P(X > Y), the chance that a seed of X scores higher than one of Y on a "
              "task (ties count half), averaged over tasks.", "", "| X | Y | P(X > Y) |", "|---|---|---|"]
    lines += [f"| {p['x']} | {p['y']} | {_cell(p, 2)} |" for p in report["improvement"]]
    for a, by_task in report["truncated"].items():
        lines += ["", f"{a}: seeds left out to equal the tasks' counts: "
                  + ", ".join(f"{t} {n}" for t, n in by_task.items()) + "."]
    prov = report["provenance"]
    lines += ["", f"Command: `{prov['command']}`. Code {prov['code']}, {prov['device']}, {prov['date']}.", ""]
    return "\n".join(lines)


# ------------------------------------------------------------------------------------------------
# The command


def cpu_description() -> str:
    """"CPU, 2 cores": where the estimates are computed (NumPy runs on the CPU even where JAX has an accelerator)."""
    cores = len(os.sched_getaffinity(0)) if hasattr(os, "sched_getaffinity") else os.cpu_count()
    return f"CPU, {cores} cores"


def compare(runs: list[tuple[str, str, str]], metric: str, out: str, reps: int = REPS, seed: int = intervals.SEED,
            gamma: float = 1.0, truncate: bool = False, command_line: str | None = None) -> dict:
    """Reads the runs, estimates with rliable, writes aggregate.png, improvement.png, comparison.json and
    comparison.md into `out`; returns the report (comparison.json's content)."""
    if not isinstance(reps, int) or reps < 1:
        raise ValueError(f"--reps {reps!r}: allowed is a positive integer.")
    if not isinstance(seed, int) or not 0 <= seed < 2**32:
        raise ValueError(f"--seed {seed!r}: allowed is an integer from 0 to 2**32 - 1.")
    if not math.isfinite(gamma):
        raise ValueError(f"--gamma {gamma!r}: allowed is a finite number.")
    scores, sources = collect(runs, metric)
    matrices, tasks, dropped = score_matrices(scores, truncate)
    report = {"metric": metric, "tasks": tasks, "algorithms": list(matrices), "reps": reps, "seed": seed,
              "gamma": gamma, "confidence": intervals.CONFIDENCE,
              "seeds": {a: int(m.shape[0]) for a, m in matrices.items()},
              "aggregate": aggregate_estimates(matrices, reps, seed, gamma),
              "improvement": improvement_estimates(matrices, reps, seed),
              "scores": {a: {t: m[:, j].tolist() for j, t in enumerate(tasks)} for a, m in matrices.items()},
              "truncated": dropped, "sources": sources,
              "provenance": {"command": command_line or command(), "code": code_version(), "device": cpu_description(),
                             "date": datetime.datetime.now(datetime.timezone.utc).date().isoformat()}}
    os.makedirs(out, exist_ok=True)
    plot_aggregate(report["aggregate"], metric, os.path.join(out, "aggregate.png"))
    plot_improvement(report["improvement"], metric, os.path.join(out, "improvement.png"))
    for name, text in (("comparison.json", json.dumps(report, indent=2) + "\n"), ("comparison.md", markdown(report))):
        with open(os.path.join(out, name), "w") as f:
            f.write(text)
    return report


def main(argv=None):
    p = argparse.ArgumentParser(prog="python -m tools.compare_runs",
                                description="rliable's aggregate metrics and probability of improvement of "
                                            "algorithms over tasks, from training runs' per-seed evaluations.")
    p.add_argument("--run", action="append", required=True, metavar="ALGO:TASK=PATH",
                   help="a run's seeds: PATH a train.py logdir, its eval.json, or a run folder of seeds-*-* parts "
                        "(repeat; the same ALGO:TASK again adds seeds)")
    p.add_argument("--metric", default="target_reached",
                   help="a per-seed key of eval.json, with or without 'episode/' (default: target_reached)")
    p.add_argument("--out", required=True, help="folder for aggregate.png, improvement.png, comparison.json/.md")
    p.add_argument("--reps", type=int, default=REPS, help=f"bootstrap resamples per interval (default: {REPS})")
    p.add_argument("--seed", type=int, default=intervals.SEED, help="seed of the resampling (default: 0)")
    p.add_argument("--gamma", type=float, default=1.0, help="optimality gap threshold (default: 1, the rates' best)")
    p.add_argument("--truncate-seeds", action="store_true",
                   help="cut an algorithm's tasks to their fewest seeds instead of refusing unequal counts")
    args = p.parse_args(argv)
    report = compare([parse_run(r) for r in args.run], args.metric, args.out, args.reps, args.seed, args.gamma,
                     args.truncate_seeds)
    print(markdown(report))


if __name__ == "__main__":
    run_cli(main)
