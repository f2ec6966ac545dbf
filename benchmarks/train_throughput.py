"""Training throughput: env steps/s of our PPO (or SAC) at the paper's setup, next to the env-only rate
of the same environment in the same run, and on 1..N local GPUs at the same per-GPU batch.

    python benchmarks/train_throughput.py --out results/train_throughput            # one GPU
    python benchmarks/train_throughput.py --devices 1 2 --out results/multi_gpu     # scaling
    python benchmarks/train_throughput.py --devices 2 --multi-device gspmd shard_map --skip-env-only
    python benchmarks/train_throughput.py --trace traces/  # + profile: benchmarks/trace_summary.py traces/1dev

Training rate: the compiled chunk of `--updates` PPO updates (rollouts, GAE, 5 epochs x 64
minibatches of gradient steps) timed after a one-update warm-up that compiles it; env steps per
second = updates x env steps per update x seeds / seconds. Env-only rate: the wrapped env stepped
with random actions (`benchmarks/env_throughput.py`), same number of envs. With several device
counts, each run keeps the per-device `num_envs` and `batch_size` of the preset, so the global
batch grows with the devices (weak scaling).
"""

from __future__ import annotations

import argparse
import dataclasses
import datetime
import json
import sys
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))
sys.path.insert(0, str(ROOT / "benchmarks"))

import jax  # noqa: E402
import jax.numpy as jnp  # noqa: E402

import train as train_cli  # noqa: E402
from agents import driver  # noqa: E402
from agents.loop import MULTI_DEVICE_MODES  # noqa: E402
from env_throughput import env_rate  # noqa: E402


def training_rate(config, updates: int, trace_dir: str | None = None) -> tuple[float, float]:
    """(env steps/s, compile seconds) of `updates` updates of the config's compiled chunk. With
    `trace_dir`, one more update runs under the JAX profiler afterwards (TensorBoard / Perfetto trace
    of where an update's time goes; not part of the timing)."""
    programs = driver.programs_for(config)
    state = programs.init(driver.seed_keys(config))
    start = time.perf_counter()
    state, metrics = programs.chunk(state, jnp.int32(1))
    jax.block_until_ready(metrics)
    compile_seconds = time.perf_counter() - start
    start = time.perf_counter()
    state, metrics = programs.chunk(state, jnp.int32(updates))
    jax.block_until_ready(metrics)
    seconds = time.perf_counter() - start
    if trace_dir:
        # The compiled program's HLO maps kernel names to JAX name scopes (benchmarks/trace_summary.py).
        Path(trace_dir).mkdir(parents=True, exist_ok=True)
        hlo = programs.chunk.lower(state, jnp.int32(1)).compile().as_text()
        (Path(trace_dir) / "chunk.hlo.txt").write_text(hlo)
        with jax.profiler.trace(trace_dir, create_perfetto_trace=True):
            state, metrics = programs.chunk(state, jnp.int32(1))
            jax.block_until_ready(metrics)
    return updates * driver.env_steps_per_update(config) * config.seeds / seconds, compile_seconds


def main():
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--preset", default="ur5e-reach-ppo")
    parser.add_argument("--updates", type=int, default=10, help="timed updates per measurement")
    parser.add_argument("--seeds", type=int, default=1)
    parser.add_argument("--devices", type=int, nargs="+", default=[1], help="device counts to measure")
    parser.add_argument("--env-steps", type=int, default=100, help="env steps per timed call of the env-only rate")
    parser.add_argument("--multi-device", nargs="+", default=["gspmd"], choices=MULTI_DEVICE_MODES,
                        help="how several devices share the work (TrainConfig.multi_device), each measured")
    parser.add_argument("--skip-env-only", action="store_true")
    parser.add_argument("--trace", metavar="DIR", help="also write a profiler trace of one update per setting to DIR/<setting>")
    parser.add_argument("--out", default="results/train_throughput")
    args = parser.parse_args()

    base = train_cli.make_config(args.preset, seeds=args.seeds, eval_envs=0, progress=False, tensorboard=False)
    rows = []
    env_only = None
    if not args.skip_env_only:
        env_only = env_rate(base.env_name, base.algo.num_envs, args.env_steps, 3, base.env.substeps)
        print(f"env only, {base.algo.num_envs} envs, 1 device: {env_only:,.0f} env steps/s", flush=True)
    # Several devices: each --multi-device mode; one device: no mode (None runs the default program).
    settings = [(d, m) for d in args.devices for m in (args.multi_device if d > 1 else [None])]
    for devices, mode in settings:
        label = f"{devices}dev" + (f"-{mode}" if mode else "")
        algo = base.algo
        if devices > 1:  # keep the per-device batch: weak scaling
            algo = dataclasses.replace(algo, num_envs=algo.num_envs * devices, batch_size=algo.batch_size * devices)
        config = dataclasses.replace(base, algo=algo, devices=devices, multi_device=mode or base.multi_device,
                                     num_timesteps=(args.updates + 1) * algo.env_steps_per_update)
        driver.validate(config)
        rate, compile_s = training_rate(config, args.updates, str(Path(args.trace) / label) if args.trace else None)
        row = {"devices": devices, "multi_device": mode, "num_envs": algo.num_envs,
               "batch_size": algo.batch_size, "seeds": args.seeds, "env_steps_per_update": algo.env_steps_per_update,
               "train_steps_per_s": rate, "compile_and_first_update_s": compile_s}
        if devices == 1 and env_only:
            row["env_only_steps_per_s"] = env_only
            row["fraction_of_env_only"] = rate / env_only
        rows.append(row)
        print(f"{label}, {algo.num_envs} envs, batch {algo.batch_size}: "
              f"{rate:,.0f} env steps/s (compile + first update {compile_s:.0f} s)", flush=True)
    for row in rows:
        row["speedup_vs_1_device"] = row["train_steps_per_s"] / rows[0]["train_steps_per_s"] if rows[0]["devices"] == 1 else None

    device = jax.devices()[0]
    meta = {"device": device.device_kind, "local_devices": jax.local_device_count(), "jax": jax.__version__,
            "date": datetime.date.today().isoformat(), "command": " ".join(["python"] + sys.argv),
            "preset": args.preset, "algo": dataclasses.asdict(base.algo), "env_name": base.env_name,
            "matmul_precision": base.matmul_precision}
    out = Path(args.out)
    out.parent.mkdir(parents=True, exist_ok=True)
    out.with_suffix(".json").write_text(json.dumps({"meta": meta, "rows": rows}, indent=2))
    lines = [f"# Training throughput: {args.preset} ({meta['device']} x{meta['local_devices']}, {meta['date']})", "",
             f"Command: `{meta['command']}`, jax {meta['jax']}, {args.seeds} seed(s), {args.updates} timed updates.", "",
             "| devices | multi-device | envs | batch | env steps/update | training env steps/s | env-only env steps/s | fraction | speed-up |",
             "|---:|---|---:|---:|---:|---:|---:|---:|---:|"]
    for r in rows:
        lines.append(f"| {r['devices']} | {r['multi_device'] or ''} | {r['num_envs']:,} | {r['batch_size']} | {r['env_steps_per_update']:,} | "
                     f"{r['train_steps_per_s']:,.0f} | {r.get('env_only_steps_per_s', float('nan')):,.0f} | "
                     f"{r.get('fraction_of_env_only', float('nan')):.0%} | {r['speedup_vs_1_device'] or float('nan'):.2f} |")
    out.with_suffix(".md").write_text("\n".join(lines) + "\n")
    print("\n".join(lines))


if __name__ == "__main__":
    main()
