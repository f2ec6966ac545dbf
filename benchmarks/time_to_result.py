"""Time to result: how long a researcher waits, per fresh seed, for a policy at a target success rate.

    python -m benchmarks.time_to_result ur5e-reach-ppo --seeds 5 --target 0.96 --out results/time_to_result/ur5e_reach_ppo
    python -m benchmarks.time_to_result point-mass-ppo --seeds 2 --target 0.8 --out /tmp/ttr -- --eval-envs 64
    python -m benchmarks.time_to_result ur5e-reach-ppo-plus --target 0.96 --stop-at 0.97 --out ...  # stop above the bar

Each seed is one `train.py PRESET --seed S --stop-at-success STOP` process of its own (STOP: `--stop-at`, by default
the target), timed from its start to its exit: importing, compiling (no persistent compilation cache unless
`--cache-dir`), training until every training episode batch reaches STOP (or the preset's budget ends) and the final
evaluation on fresh episodes. Options after `--` go to train.py unchanged. Reported per seed: the wall clock, the
training's own clock (its chunks of updates, the first with the compiling left once the state is initialised; the rest
is start-up, checkpoints and the final evaluation), the env steps trained, the training success at the stop and the
evaluation's success; a seed counts as a result when its evaluation reaches the target.

Writes `--out`.json (every seed, command, code version, device, date) and `--out`.md (the table).
"""

from __future__ import annotations

import argparse
import csv
import json
import os
import shlex
import subprocess
import sys
import tempfile
import time

import numpy as np

from agents import provenance
from agents.eval_stats import jsonable
from agents.presets import PRESETS
from tools import run_cli

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))


def train_command(preset: str, seed: int, target: float, logdir: str, extra: list[str]) -> list[str]:
    """The train.py command line of one seed."""
    return [sys.executable, os.path.join(ROOT, "train.py"), preset, "--seed", str(seed), "--seeds", "1",
            "--stop-at-success", str(target), "--logdir", logdir, "--no-progress", "--no-tensorboard", *extra]


def run_seed(preset: str, seed: int, target: float, logdir: str, extra: list[str], cache_dir: str | None,
             stop_at: float | None = None) -> dict:
    """One seed's process, stopped at the training success `stop_at` (default `target`): its wall clock and what its
    eval.json and metrics.csv say; its evaluation is held against `target`."""
    env = dict(os.environ)
    # An empty value turns the cache off: left unset, train.py would use the repository's .jax_cache/.
    env["JAX_COMPILATION_CACHE_DIR"] = cache_dir or ""
    command = train_command(preset, seed, target if stop_at is None else stop_at, logdir, extra)
    start = time.perf_counter()
    done = subprocess.run(command, env=env, capture_output=True, text=True)
    seconds = time.perf_counter() - start
    if done.returncode != 0:
        raise RuntimeError(f"seed {seed}: train.py exited with {done.returncode}: {done.stderr.strip()[-2000:]}")
    with open(os.path.join(logdir, "eval.json")) as f:
        report = json.load(f)
    with open(os.path.join(logdir, "metrics.csv")) as f:
        log = list(csv.DictReader(f))
    evaluated = float(report["mean"]["episode/target_reached"])
    return {"seed": seed, "wall_seconds": seconds, "env_steps": int(report["env_steps"]),
            "training_success": float(log[-1]["episode/target_reached"]),  # the training episodes at the last log
            "eval_success": evaluated, "reached_target": evaluated >= target, **training_clock(log),
            "command": " ".join(shlex.quote(c) for c in command[1:])}


def training_clock(rows: list[dict]) -> dict:
    """Where a one-seed run's training time went, from its metrics.csv `rows`' `wall_seconds` (each log's chunk of
    updates, the first one's compiling included, less what ran beside init): the first chunk, all chunks, and the
    env steps per second after the first."""
    seconds = [float(r["wall_seconds"]) for r in rows]
    steps = float(rows[-1]["env_steps"]) - float(rows[0]["env_steps"])
    return {"first_log_seconds": seconds[0], "first_log_env_steps": int(float(rows[0]["env_steps"])),
            "training_seconds": sum(seconds),
            "steps_per_second_after_first_log": steps / sum(seconds[1:]) if len(seconds) > 1 else None}


def summary(rows: list[dict]) -> dict:
    """Mean, sample std (ddof 1) and max of the wall clocks; how many seeds' evaluations reached the target."""
    wall = np.array([r["wall_seconds"] for r in rows])
    return {"seeds": len(rows), "wall_mean": float(wall.mean()), "wall_std": float(np.std(wall, ddof=1)) if len(wall) > 1 else None,
            "wall_max": float(wall.max()), "reached": int(sum(r["reached_target"] for r in rows))}


def markdown(preset: str, target: float, rows: list[dict], stamp: dict, stop_at: float | None = None,
             xla_flags: str = "") -> str:
    """The table of `rows` under a line naming the command, code version, device and date of `stamp` (and the
    XLA_FLAGS the seeds ran with, when set)."""
    s = summary(rows)
    stop = "" if stop_at in (None, target) else f" (training stopped at {100 * stop_at:.1f} % success)"
    flags = f" XLA_FLAGS: `{xla_flags}`." if xla_flags else ""
    lines = [f"`{preset}` to {100 * target:.1f} % reached{stop}", "",
             f"Command: `{stamp['command']}`; code {stamp['code']}; {stamp['device']}; {stamp['date']}.{flags}", "",
             "| seed | wall clock (s) | training chunks (s) | first chunk (s, compiling left after init included) | env steps | training success at the stop "
             "| evaluation reached | target met |",
             "|---:|---:|---:|---:|---:|---:|---:|---|"]
    for r in rows:
        lines.append(f"| {r['seed']} | {r['wall_seconds']:.0f} | {r['training_seconds']:.0f} | "
                     f"{r['first_log_seconds']:.0f} at {r['first_log_env_steps']:,} steps | {r['env_steps']:,} | "
                     f"{100 * r['training_success']:.1f} % | {100 * r['eval_success']:.1f} % | "
                     f"{'yes' if r['reached_target'] else 'no'} |")
    std = "" if s["wall_std"] is None else f" ± {s['wall_std']:.0f}"
    lines += ["", f"Wall clock {s['wall_mean']:.0f}{std} s (mean ± sample std over {s['seeds']} seeds), at most "
                  f"{s['wall_max']:.0f} s; {s['reached']} of {s['seeds']} seeds' evaluations reached the target."]
    return "\n".join(lines) + "\n"


def main(argv: list[str] | None = None) -> int:
    argv = list(sys.argv[1:] if argv is None else argv)
    extra = argv[argv.index("--") + 1:] if "--" in argv else []
    argv = argv[:argv.index("--")] if "--" in argv else argv
    p = argparse.ArgumentParser(prog="python -m benchmarks.time_to_result", description=__doc__.split("\n\n")[0])
    p.add_argument("preset")
    p.add_argument("--seeds", type=int, default=5, help="fresh seeds, one process each")
    p.add_argument("--first-seed", type=int, default=100, help="the first seed (seeds the presets' runs did not use)")
    p.add_argument("--target", type=float, required=True, help="success rate the evaluation must reach")
    p.add_argument("--stop-at", type=float, default=None,
                   help="training success to stop at (default: the target; sampled actions on training episodes "
                        "succeed less or more often than the evaluation's deterministic policy)")
    p.add_argument("--out", required=True, help="path prefix of the .json and .md written")
    p.add_argument("--cache-dir", default=None, help="a persistent compilation cache (default: none, a cold start)")
    p.add_argument("--logdir", default=None, help="where the runs go (default: a temporary folder, removed)")
    args = p.parse_args(argv)
    if args.preset not in PRESETS:
        raise ValueError(f"preset={args.preset!r} is unknown: allowed are {', '.join(sorted(PRESETS))}.")
    if args.seeds < 1:
        raise ValueError(f"--seeds={args.seeds} is invalid: allowed is an integer >= 1.")
    if not 0.0 < args.target <= 1.0:
        raise ValueError(f"--target={args.target} is invalid: allowed is a success rate in (0, 1].")
    if args.stop_at is not None and not 0.0 < args.stop_at <= 1.0:
        raise ValueError(f"--stop-at={args.stop_at} is invalid: allowed is a success rate in (0, 1].")
    stop_at = args.target if args.stop_at is None else args.stop_at
    xla_flags = os.environ.get("XLA_FLAGS", "")  # as the seeds' processes inherit them (agents/xla_flags.py adds its own)
    os.makedirs(os.path.dirname(os.path.abspath(args.out)), exist_ok=True)
    rows = []
    with tempfile.TemporaryDirectory() as tmp:
        base = args.logdir or tmp
        for seed in range(args.first_seed, args.first_seed + args.seeds):
            rows.append(run_seed(args.preset, seed, args.target, os.path.join(base, f"seed{seed}"), extra,
                                 args.cache_dir, stop_at))
            print(f"seed {seed}: {rows[-1]['wall_seconds']:.0f} s, {rows[-1]['env_steps']:,} env steps, "
                  f"evaluation {100 * rows[-1]['eval_success']:.1f} %", flush=True)
            stamp = provenance.stamp()
            report = {**stamp, "preset": args.preset, "target": args.target,
                      "stop_at": stop_at, "train_options": extra, "cache_dir": args.cache_dir,
                      "xla_flags": xla_flags, "seeds": rows, "summary": summary(rows)}
            with open(args.out + ".json", "w") as f:  # after every seed: a run cut short keeps what it finished
                json.dump(jsonable(report), f, indent=2)
            with open(args.out + ".md", "w") as f:
                f.write(markdown(args.preset, args.target, rows, stamp, stop_at, xla_flags))
    print(markdown(args.preset, args.target, rows, stamp, stop_at, xla_flags))
    return 0


if __name__ == "__main__":
    run_cli(main)
