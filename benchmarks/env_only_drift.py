"""How the env-only rate of one process moves with what else the process did on the GPU.

    python benchmarks/env_only_drift.py        # on the GPU machine; one line per timing

The env-only rollout of `benchmarks/env_throughput.py` (the `ur5e-reach-ppo` preset's env, 8,192
envs, 100 steps per call, median of three calls) is timed again and again in one process: fresh,
after the training chunk compiled and ran one update, after 10 training updates, after 10 s idle,
with fresh copies of its input buffers, after the training state was freed, after temporary 1 GiB
allocations and after 8 s of other GPU work. The compiled programs stay the same throughout; the
GPU's clocks can be watched beside it (`nvidia-smi --query-gpu=clocks.sm,clocks_event_reasons.active
-lms 250`). On an H200 the rate moved between three levels, 1.06M, 1.12M and 1.14M env steps/s
(results/speed_history/README.md, "13"), with XLA's memory pool on or off, which is why
train_throughput.py alternates its timings.
"""

from __future__ import annotations

import dataclasses
import datetime
import gc
import sys
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))
sys.path.insert(0, str(ROOT / "benchmarks"))

import agents  # noqa: E402,F401  (first: the project's XLA settings, as in training)
import jax  # noqa: E402
import jax.numpy as jnp  # noqa: E402

import train as train_cli  # noqa: E402
from env_throughput import env_rollout, time_calls  # noqa: E402
from train_throughput import Training  # noqa: E402

STEPS = 100
"""Env steps per timed call of the env-only rollout."""


def main():
    base = train_cli.make_config("ur5e-reach-ppo", seeds=1, eval_envs=0, progress=False, tensorboard=False)
    num_envs = base.algo.num_envs
    fn, args = env_rollout(base.env_name, num_envs, STEPS, config=base.env)

    def env_only(label, call_args=args):
        start = time.time()
        rate = num_envs * STEPS / time_calls(fn, call_args, 3)
        now = datetime.datetime.now().strftime("%H:%M:%S.%f")[:-3]
        print(f"{now} {label:45s} {rate:12,.0f}  ({time.time() - start:.1f}s)", flush=True)

    def train(run, updates=10):
        print(f"train {updates} updates {run.time(updates):,.0f}", flush=True)

    env_only("A fresh (compiles)")
    env_only("A2 fresh again")
    env_only("A3 fresh again")
    run = Training(dataclasses.replace(base, num_timesteps=200 * base.algo.env_steps_per_update))  # compiles, 1 update
    env_only("B after compile + 1 update")
    train(run)
    env_only("C after 10 updates")
    env_only("C2 again")
    time.sleep(10)
    env_only("D after 10 s idle")
    train(run)
    env_only("E after 10 more updates")
    fresh = jax.block_until_ready(jax.tree.map(jnp.copy, args))
    env_only("F fresh copies of the env state", fresh)
    env_only("F2 original buffers again")
    del run
    gc.collect()
    env_only("G after the training state was freed")
    for k in range(3):
        jax.block_until_ready(jnp.ones((1 << 28,)) * 2)  # 1 GiB of float32, freed at once
        env_only(f"H{k} after a 1 GiB temp alloc")
    start = time.time()
    while time.time() - start < 8:
        jax.block_until_ready(jnp.sum(jnp.sin(jnp.ones((1 << 26,)))))
    env_only("I after 8 s of other GPU work")


if __name__ == "__main__":
    main()
