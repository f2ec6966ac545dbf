"""Experiments as code: each of the paper's tables and figures (and our own studies) is a named `Experiment`
(registered in `tools/registry_paper_tasks.py` and `tools/registry_obstacles.py`): its training runs (`Run`:
preset, overrides, seeds, budget), cross-evaluations and the table and figure built from them.

    python -m tools.experiments list                                 # every experiment: done, partly trained, missing
    python -m tools.experiments launch reward                        # one Slurm job per part still to train
    python -m tools.experiments launch reward --executor local       # this machine: one part per GPU at a time
    python -m tools.experiments run point-mass-demo                  # in this process, part after part
    python -m tools.experiments build reward                         # table.md, table.json, curves.png
    python -m tools.experiments commands reward                      # one train.py command per part, to run by hand
    python -m tools.experiments record --runs-dir OTHER/runs/experiments   # finished parts into the results

A name selects an experiment (`action-space`) or one of its runs (`action-space/relative`); none selects all. A
run trains in parts, `<runs-dir>/<experiment>/<run>/seeds-<first>-<last>/` (`--max-seeds K`: at most K seeds
trained together in one process); `tools/experiment_state.py` reads their state, `tools/experiment_launch.py`
trains them, `tools/experiment_tables.py` builds the tables into `<out>/<experiment>/`.
"""

from __future__ import annotations

import argparse
import os
import shlex
import sys

from agents import xla_flags
from tools import run_cli
from tools.experiment_launch import EXECUTORS, LaunchConfig, describe_job, launch, run_parts
from tools.experiment_state import (
    OUT_DIR, RUNS_DIR, RunState, checkpoint_steps, millions, pending_parts, planners, run_state, select, table_built,
    validate_experiment,
)
from tools.experiment_tables import build, cross_files, record


def describe_state(st: RunState) -> str:
    """'done', 'partial 2/5 seeds done, 60M/150M', 'changed (...)', with the run it shares and its parts' jobs."""
    text = st.status
    if st.status == "partial":
        done = f"{st.seeds_done}/{st.run.seeds} seeds done" if st.seeds_done else ""
        text += " " + ", ".join(x for x in (done, f"{millions(st.steps)}/{millions(st.budget)}" if st.steps else "") if x)
    if st.reason:
        text += f" ({st.reason})"
    jobs = [f"{p.name}: {note}" for p in st.parts if p.status != "done" for note in [describe_job(p.logdir)] if note]
    return text + (f" [trains in {st.shared}]" if st.shared else "") + "".join(f"; {j}" for j in jobs)


def cross_status(st: RunState, cross, out: str) -> str:
    """A cross-evaluation's progress: 'after training', 'done', or how many parts are evaluated and where."""
    files = cross_files(st, cross, out)
    left = [p for p in st.done_parts if p.name not in files]
    here = sum(bool(checkpoint_steps(p.logdir)) for p in left)
    if not st.done_parts:
        return "after training"
    if st.status == "done" and not left:
        return "done"
    return (f"{len(files)} of {len(st.done_parts)} parts evaluated; {here} to evaluate here (`launch` or `run`), "
            f"{len(left) - here} "
            "without checkpoints here (evaluated where they are, or retrained)")


def listing(selection, runs_dir: str, out: str, registry: dict | None = None) -> str:
    """Every selected experiment with its runs' states and the env steps they cost (a folder shared by several runs
    counted once, with the most seeds any of them needs)."""
    lines, need, trained = [], {}, {}
    for exp, runs in selection:
        states = [run_state(exp, r, runs_dir, out, registry) for r in runs]
        counts = {s: sum(st.status == s for st in states) for s in ("done", "trained", "partial", "missing", "changed")}
        lines.append(f"{exp.name}: {exp.title} [{exp.paper_ref}]")
        lines.append(f"  {', '.join(f'{n} {s}' for s, n in counts.items() if n)}; "
                     f"table {'built' if table_built(exp, out) else 'not built'}")
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
            lines.append(f"  cross {cross.name}: {cross.run} with {cross.setting}: {cross_status(st, cross, out)}")
    total = sum(need.values())
    done = sum(min(trained[f], need[f]) for f in need)
    lines.append(f"total: {total:,} env steps ({total / 1e9:.2f}B), {done:,} trained"
                 + ("; nothing left" if done >= total else ""))
    return "\n".join(lines)


def commands(selection, runs_dir: str, everything: bool = False, max_seeds: int | None = None,
             out: str | None = None, registry: dict | None = None) -> list[str]:
    """One `python train.py ...` per part still to train (with `everything`, every part of every run, each as a
    fresh run); unfinished parts get --resume. Runs sharing a folder are planned once (`planners`)."""
    lines = []
    for _, st in planners(selection, runs_dir, out, registry, with_changed=everything):
        if everything:
            st = RunState(st.experiment, st.run, st.folder, "missing", 0, st.budget, [], st.shared)
        for part in pending_parts(st, max_seeds):
            args = st.run.train_args(part.logdir, resume=part.steps > 0 and not everything, first_seed=part.first,
                                     seeds=part.count)
            if part.steps == 0 and os.path.isdir(part.logdir) and os.listdir(part.logdir):
                args.append("--overwrite")  # stopped before its first checkpoint: only logs to replace
            lines.append(shlex.join(["python", "train.py", *args]))
    return lines


ACTION_FLAGS = {"executor": ("launch",), "time": ("launch",), "partition": ("launch",), "gpus_per_part": ("launch",),
                "cpus_per_part": ("launch",), "max_requeues": ("launch",), "signal_delay": ("launch",),
                "slurm_arg": ("launch",), "wait": ("launch",), "jobs_dir": ("launch",),
                "compilation_cache": ("launch", "run"), "no_build": ("run",), "all": ("commands",),
                "max_seeds": ("launch", "run", "commands")}
"""Options that mean something only to some actions."""


def parser() -> argparse.ArgumentParser:
    p = argparse.ArgumentParser(prog="python -m tools.experiments", description=__doc__.split("\n\n")[0])
    p.add_argument("action", choices=("list", "launch", "run", "commands", "build", "record"))
    p.add_argument("names", nargs="*", help="experiments or experiment/run (default: all)")
    p.add_argument("--runs-dir", default=RUNS_DIR, help=f"where runs are trained (default {RUNS_DIR})")
    p.add_argument("--out", default=OUT_DIR, help=f"where tables, figures and finished parts go (default {OUT_DIR})")
    p.add_argument("--executor", choices=EXECUTORS, help="launch: slurm (default) or local (this machine's GPUs)")
    p.add_argument("--time", type=int, help="launch: each job's time limit in minutes (default 240); longer parts "
                   "are requeued and resume from their checkpoint")
    p.add_argument("--partition", help="launch: the Slurm partition (default: the cluster's)")
    p.add_argument("--gpus-per-part", type=int, help="launch: GPUs per job (default 1; 0: the CPU)")
    p.add_argument("--cpus-per-part", type=int, help="launch: CPU cores per Slurm job (default: the cluster's)")
    p.add_argument("--max-requeues", type=int, help="launch: requeues after a time limit before a job gives up "
                   "(default 10)")
    p.add_argument("--signal-delay", type=int, help="launch: seconds before the time limit that a job is told to "
                   "checkpoint (default: a quarter of the limit, at most 120)")
    p.add_argument("--slurm-arg", action="append", metavar="KEY=VALUE", help="launch: a further sbatch option, "
                   "e.g. account=rl (repeatable)")
    p.add_argument("--wait", action="store_true", help="launch --executor slurm: wait until the jobs have ended")
    p.add_argument("--jobs-dir", help="launch: submitit's folder for job scripts and logs (default <runs-dir>/jobs)")
    p.add_argument("--compilation-cache", metavar="DIR", help="launch, run: JAX's persistent compilation cache "
                   "(default: $JAX_COMPILATION_CACHE_DIR, empty for none, else .jax_cache/ in the repository; 'off' for none)")
    p.add_argument("--max-seeds", type=int, help="launch, run, commands: seeds trained together in one process "
                   "(default: all of a run's; 1 trains each seed on its own)")
    p.add_argument("--no-build", action="store_true", help="run: no tables afterwards (finished parts are recorded)")
    p.add_argument("--all", action="store_true", help="commands: also the runs done (each as a fresh run)")
    return p


def launch_config(args) -> LaunchConfig:
    """The LaunchConfig of the command line's launch options (ValueError naming a bad one)."""
    pairs = []
    for item in args.slurm_arg or ():
        key, sep, value = item.partition("=")
        if not sep or not key:
            raise ValueError(f"--slurm-arg={item!r} is invalid: allowed is KEY=VALUE (an sbatch option without dashes).")
        pairs.append((key, value))
    given = dict(executor=args.executor, time_min=args.time, partition=args.partition, gpus_per_part=args.gpus_per_part,
                 cpus_per_part=args.cpus_per_part, max_requeues=args.max_requeues, signal_delay_s=args.signal_delay,
                 slurm_args=tuple(pairs), wait=args.wait, folder=args.jobs_dir)
    config = LaunchConfig(**{k: v for k, v in given.items() if v is not None and v != ()})
    if config.executor == "local" and config.wait:
        raise ValueError("--wait with --executor local is meaningless: the local executor always waits.")
    return config


def main(argv=None) -> int:
    args = parser().parse_args(argv)
    if args.max_seeds is not None and args.max_seeds < 1:
        raise ValueError(f"--max-seeds={args.max_seeds} is impossible: allowed is 1 or more (or leave it out).")
    for flag, actions in ACTION_FLAGS.items():
        given = getattr(args, flag)
        if given is not None and given is not False and args.action not in actions:
            raise ValueError(f"--{flag.replace('_', '-')} with {args.action} is meaningless: allowed is "
                             f"{' or '.join(f'`{a}`' for a in actions)} with it.")
    selection = select(args.names)
    if args.action in ("launch", "run", "commands"):
        for exp, _ in selection:  # every config built and checked before anything is submitted or trained
            validate_experiment(exp)
    if args.action == "list":
        print(listing(selection, args.runs_dir, args.out))
    elif args.action == "commands":
        print("\n".join(commands(selection, args.runs_dir, args.all, args.max_seeds, args.out)))
    elif args.action == "build":
        if not build(selection, args.runs_dir, args.out):
            names = ", ".join(exp.name for exp, _ in selection)
            print(f"nothing built: no run of {names} has a finished part in --runs-dir {args.runs_dir!r} or "
                  f"--out {args.out!r} (`list` shows what is done)", file=sys.stderr)
            return 1
    elif args.action == "record":
        if not os.path.isdir(args.runs_dir):
            raise ValueError(f"--runs-dir={args.runs_dir!r} is not a folder: allowed is a runs folder to record from.")
        written = record(selection, args.runs_dir, args.out)
        print("\n".join([f"recorded {path}" for path in written]
                        + [f"{len(written)} files recorded from {args.runs_dir} into {args.out}"]))
    elif args.action == "launch":
        config = launch_config(args)  # validated before anything is submitted
        launch(selection, config, args.runs_dir, args.out, args.max_seeds, args.compilation_cache)
        if config.executor == "local" or config.wait:
            left = [st.key for exp, runs in selection for r in runs
                    for st in [run_state(exp, r, args.runs_dir, args.out)] if st.status != "done"]
            if left:
                print(f"not finished: {', '.join(left)} (`list` says why; `launch` again continues)", file=sys.stderr)
                return 1
    else:
        xla_flags.compilation_cache(args.compilation_cache)
        finished = run_parts(selection, args.runs_dir, args.out, args.max_seeds)
        if not args.no_build:
            build(selection, args.runs_dir, args.out, complete_only=True)
        if not finished:
            print("not finished: `python -m tools.experiments run` again continues.", file=sys.stderr)
    return 0


if __name__ == "__main__":
    run_cli(main)
