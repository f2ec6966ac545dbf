"""Training throughput: env steps/s of our PPO (or SAC) at the paper's setup, next to the env-only rate
of the same environment in the same run, and on 1..N local GPUs at the same per-GPU batch.

    python -m benchmarks.train_throughput --out results/throughput/train_throughput            # one GPU
    python -m benchmarks.train_throughput --devices 1 2 --out results/throughput/multi_gpu     # scaling
    python -m benchmarks.train_throughput --devices 2 --multi-device gspmd shard_map --skip-env-only
    python -m benchmarks.train_throughput --trace traces/  # + profile: python -m benchmarks.trace_summary traces/1dev
    python -m benchmarks.train_throughput --preset ur5e-reach-sac-fast --variant compute_dtype=float32  # A/B, same rounds
    python -m benchmarks.train_throughput --preset panda-reach-sac --seeds 1 2 5  # seeds vmapped in one program

Training rate: the compiled chunk of `--updates` PPO updates (rollouts, GAE, the preset's epochs of
minibatch gradient steps), timed after a one-update warm-up that compiles it; env steps per
second = updates x env steps per update x seeds / seconds. Env-only rate: the preset's own env
config (same substeps, action scale, reward terms), wrapped as in training (episode limit, fresh
auto-reset, vmap) and stepped with uniform random actions (`benchmarks/env_throughput.py`), same
number of envs. Everything is compiled first; then `--rounds` rounds each time the env alone
(median of three calls) and every setting once, so that a drift of the GPU's speed during the
process (results: throughput study) falls on both sides of each round's ratio. Reported: per-round
figures, their medians, and the fraction of env-only = the median of the rounds' ratios, written
after every round (a run cut off by a time limit keeps the rounds it finished). With
several device counts, each run keeps the per-device `num_envs` and `batch_size` of the preset, so
the global batch grows with the devices (weak scaling). Several `--seeds` counts: each is a setting
(seeds trained together in one vmapped program, as `train.py --seeds N`), its rate counted over all seeds
and per seed, to choose how many seeds a process should train. Speed-up: against one device at the same
seed count (a `--variant` row: against the preset itself).
"""

from __future__ import annotations

import argparse
import dataclasses
import datetime
import json
import os
import statistics
import sys
import time
from pathlib import Path

import jax
import jax.numpy as jnp

from agents import config as config_lib, driver, presets, provenance
from agents.loop import MULTI_DEVICE_MODES
from benchmarks.env_throughput import env_rollout, time_calls
from tools import literal_or_text


def cell(value, spec: str) -> str:
    """A table cell: the value formatted, or blank where it was not measured (--skip-env-only)."""
    return "" if value is None else format(value, spec)


class Training:
    """One setting's compiled chunk and its state; `time(updates)` runs `updates` updates and
    returns env steps/s."""

    def __init__(self, config):
        self.config = config
        self.programs = driver.programs_for(config)
        self.state = self.programs.init(driver.seed_keys(config))
        start = time.perf_counter()
        self.state, metrics = self.programs.chunk(self.state, jnp.int32(1))  # compiles
        jax.block_until_ready(metrics)
        self.compile_seconds = time.perf_counter() - start

    def time(self, updates: int) -> float:
        start = time.perf_counter()
        self.state, metrics = self.programs.chunk(self.state, jnp.int32(updates))
        jax.block_until_ready(metrics)
        seconds = time.perf_counter() - start
        return updates * config_lib.env_steps_per_update(self.config) * self.config.seeds / seconds

    def trace(self, trace_dir: str) -> None:
        """One more update under the JAX profiler (not part of the timing): `trace_chunk`."""
        self.state = trace_chunk(self.programs, self.state, 1, trace_dir)


def trace_chunk(programs, state, updates: int, trace_dir: str):
    """Runs `updates` updates of `programs.chunk` under the JAX profiler (TensorBoard / Perfetto trace of where
    their time goes) and writes the compiled program's HLO beside it, which maps kernel names to JAX name scopes
    (benchmarks/trace_summary.py); returns the state after them."""
    Path(trace_dir).mkdir(parents=True, exist_ok=True)
    n = jnp.int32(updates)
    (Path(trace_dir) / "chunk.hlo.txt").write_text(programs.chunk.lower(state, n).compile().as_text())
    with jax.profiler.trace(trace_dir, create_perfetto_trace=True):
        state, metrics = programs.chunk(state, n)
        jax.block_until_ready(metrics)
    return state


def parse_variant(text: str, algo) -> dict:
    """{field: value} from "compute_dtype=bfloat16,q_hidden_sizes=(256,256,256)" (Python literals, else strings);
    ValueError naming an unknown field of the preset's algo config."""
    fields = [f.name for f in dataclasses.fields(algo)]
    out, parts, depth, current = {}, [], 0, ""
    for char in text:  # split on the commas outside brackets
        if char in "([":
            depth += 1
        elif char in ")]":
            depth -= 1
        if char == "," and depth == 0:
            parts.append(current)
            current = ""
        else:
            current += char
    parts.append(current)
    for part in parts:
        name, sep, value = part.partition("=")
        name = name.strip().replace("-", "_")
        if not sep or name not in fields:
            raise ValueError(f"--variant {text!r}: {name!r} is not a field of {type(algo).__name__}: allowed are "
                             f"{', '.join(fields)} (as FIELD=VALUE).")
        out[name] = literal_or_text(value.strip())
    return out


def main():
    parser = argparse.ArgumentParser(prog="python -m benchmarks.train_throughput", description=__doc__.split("\n\n")[0])
    parser.add_argument("--preset", default="ur5e-reach-ppo")
    parser.add_argument("--updates", type=int, default=10, help="timed updates per measurement")
    parser.add_argument("--rounds", type=int, default=3, help="rounds of (env only, every setting) timings")
    parser.add_argument("--seeds", type=int, nargs="+", default=[1],
                        help="seeds trained together in one program; several counts: each measured (variants use the first)")
    parser.add_argument("--devices", type=int, nargs="+", default=[1], help="device counts to measure")
    parser.add_argument("--env-steps", type=int, default=100, help="env steps per timed call of the env-only rate")
    parser.add_argument("--multi-device", nargs="+", default=["gspmd"], choices=MULTI_DEVICE_MODES,
                        help="how several devices share the work (TrainConfig.multi_device), each measured")
    parser.add_argument("--skip-env-only", action="store_true")
    parser.add_argument("--variant", action="append", default=[], metavar="FIELD=VALUE[,FIELD=VALUE]",
                        help="also time the preset with these algo fields changed, on one device in the same rounds "
                             "(repeatable), e.g. --variant compute_dtype=bfloat16 --variant 'q_hidden_sizes=(256,256,256)'")
    parser.add_argument("--trace", metavar="DIR", help="also write a profiler trace of one update per setting to DIR/<setting>")
    parser.add_argument("--out", default="results/throughput/train_throughput")
    args = parser.parse_args()
    if args.updates < 1 or args.rounds < 1 or args.env_steps < 1 or min(args.seeds) < 1:
        parser.error(f"--updates, --rounds, --env-steps and --seeds must be >= 1, got {args.updates}, {args.rounds}, "
                     f"{args.env_steps}, {args.seeds}")

    base = presets.make_config(args.preset, seeds=args.seeds[0], eval_envs=0, progress=False, tensorboard=False)
    # Several devices: each --multi-device mode; one device: no mode (None runs the default program).
    settings = {}
    for seeds in dict.fromkeys(args.seeds):
        for devices in args.devices:
            for mode in (args.multi_device if devices > 1 else [None]):
                algo = base.algo
                if devices > 1:  # keep the per-device batch: weak scaling
                    algo = dataclasses.replace(algo, num_envs=algo.num_envs * devices, batch_size=algo.batch_size * devices)
                config = dataclasses.replace(base, algo=algo, seeds=seeds, devices=devices,
                                             multi_device=mode or base.multi_device,
                                             num_timesteps=(args.rounds * args.updates + 2) * algo.env_steps_per_update)
                config_lib.validate(config)  # every setting before the first compile
                label = f"{devices}dev" + (f"-{mode}" if mode else "") + (f" {seeds} seeds" if len(args.seeds) > 1 else "")
                settings[label] = (devices, mode, config, None)

    for text in args.variant:
        algo = dataclasses.replace(base.algo, **parse_variant(text, base.algo))
        config = dataclasses.replace(base, algo=algo, num_timesteps=(args.rounds * args.updates + 2) * algo.env_steps_per_update)
        config_lib.validate(config)
        settings[f"1dev {text}"] = (1, None, config, text)

    env_only = None
    if not args.skip_env_only:
        env_fn, env_args = env_rollout(base.env_name, base.algo.num_envs, args.env_steps, config=base.env)
        env_time = lambda: base.algo.num_envs * args.env_steps / time_calls(env_fn, env_args, 3)
        jax.block_until_ready(env_fn(*env_args))  # compiles
        env_only = []
    runs = {}
    for label, (_, _, config, _) in settings.items():
        runs[label] = Training(config)
        print(f"{label}: compile + first update {runs[label].compile_seconds:.0f} s", flush=True)
    rates = {label: [] for label in settings}
    for r in range(args.rounds):
        line = []
        if env_only is not None:
            env_only.append(env_time())
            line.append(f"env only {env_only[-1]:,.0f}")
        for label, run in runs.items():
            rates[label].append(run.time(args.updates))
            line.append(f"{label} {rates[label][-1]:,.0f}")
        print(f"round {r + 1}: " + ", ".join(line) + " env steps/s", flush=True)
        # After every round, so that a run stopped by a time limit keeps the rounds it finished.
        text = write_report(Path(args.out), args, base, settings, runs, rates, env_only)
    print(text)
    if args.trace:
        for label, run in runs.items():
            run.trace(str(Path(args.trace) / label))


def write_report(out: Path, args, base, settings: dict, runs: dict, rates: dict, env_only: list | None) -> str:
    """`out`.json and `out`.md from the rounds timed so far (medians over them); returns the markdown."""
    rows = []
    for label, (devices, mode, config, variant) in settings.items():
        algo = config.algo
        row = {"setting": label, "devices": devices, "multi_device": mode, "variant": variant, "num_envs": algo.num_envs,
               "batch_size": algo.batch_size, "seeds": config.seeds, "env_steps_per_update": algo.env_steps_per_update,
               "train_steps_per_s": statistics.median(rates[label]), "train_steps_per_s_rounds": rates[label],
               "train_steps_per_s_per_seed": statistics.median(rates[label]) / config.seeds,
               "compile_and_first_update_s": runs[label].compile_seconds}
        if devices == 1 and env_only:
            ratios = [t / e for t, e in zip(rates[label], env_only)]
            row.update(env_only_steps_per_s=statistics.median(env_only), env_only_steps_per_s_rounds=env_only,
                       fraction_of_env_only=statistics.median(ratios), fraction_of_env_only_rounds=ratios)
        rows.append(row)
    one_device = {r["seeds"]: r["train_steps_per_s"] for r in rows if r["devices"] == 1 and r["variant"] is None}
    for row in rows:  # against one device at the same seed count
        base_rate = one_device.get(row["seeds"])
        row["speedup_vs_1_device"] = row["train_steps_per_s"] / base_rate if base_rate else None

    rounds = len(next(iter(rates.values())))
    device = jax.devices()[0]
    meta = {"device": device.device_kind, "local_devices": jax.local_device_count(), "jax": jax.__version__,
            "date": datetime.date.today().isoformat(),
            "command": " ".join(["python", "-m", "benchmarks.train_throughput"] + sys.argv[1:]),
            "code": provenance.code_version(),
            "preset": args.preset, "updates": args.updates, "rounds": rounds, "rounds_asked": args.rounds,
            "env_steps": args.env_steps, "algo": dataclasses.asdict(base.algo), "env_name": base.env_name,
            "env": dataclasses.asdict(base.env), "matmul_precision": base.matmul_precision,
            "xla_flags": os.environ.get("XLA_FLAGS", "")}  # as XLA read them (agents/xla_flags.py adds its own)
    out.parent.mkdir(parents=True, exist_ok=True)
    out.with_suffix(".json").write_text(json.dumps({"meta": meta, "rows": rows}, indent=2))
    lines = [f"# Training throughput: {args.preset} ({meta['device']} x{meta['local_devices']}, {meta['date']})", "",
             f"Command: `{meta['command']}`, jax {meta['jax']}, {'/'.join(map(str, args.seeds))} seed(s), {rounds} rounds"
             + (f" (of {args.rounds} asked)" if rounds < args.rounds else "")
             + f" of {args.updates} timed updates; medians over the rounds (fraction: median of the rounds' ratios)."
             + (f" XLA_FLAGS: `{meta['xla_flags']}`." if meta["xla_flags"] else ""), "",
             "| setting | devices | multi-device | envs | batch | seeds | env steps/update | training env steps/s (all seeds) | per seed | env-only env steps/s | fraction | speed-up |",
             "|---|---:|---|---:|---:|---:|---:|---:|---:|---:|---:|---:|"]
    for r in rows:
        lines.append(f"| {r['setting']} | {r['devices']} | {r['multi_device'] or ''} | {r['num_envs']:,} | {r['batch_size']} | {r['seeds']} | {r['env_steps_per_update']:,} | "
                     f"{r['train_steps_per_s']:,.0f} | {r['train_steps_per_s_per_seed']:,.0f} | {cell(r.get('env_only_steps_per_s'), ',.0f')} | "
                     f"{cell(r.get('fraction_of_env_only'), '.1%')} | {cell(r['speedup_vs_1_device'], '.2f')} |")
    text = "\n".join(lines) + "\n"
    out.with_suffix(".md").write_text(text)
    return text


if __name__ == "__main__":
    main()
