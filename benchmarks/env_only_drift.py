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
import dataclasses, gc, sys, time, datetime
from pathlib import Path
ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT)); sys.path.insert(0, str(ROOT / "benchmarks"))
import agents  # noqa
import jax, jax.numpy as jnp
import train as train_cli
from agents import driver
from env_throughput import env_rollout, time_calls

base = train_cli.make_config("ur5e-reach-ppo", seeds=1, eval_envs=0, progress=False, tensorboard=False)
N, S = base.algo.num_envs, 100
fn, args = env_rollout(base.env_name, N, S, config=base.env)

def env(label, a=None):
    t0 = time.time()
    r = N * S / time_calls(fn, a or args, 3)
    print(f"{datetime.datetime.now().strftime('%H:%M:%S.%f')[:-3]} {label:45s} {r:12,.0f}  ({time.time()-t0:.1f}s)", flush=True)

env("A fresh (compiles)")
env("A2 fresh again")
env("A3 fresh again")
cfg = dataclasses.replace(base, num_timesteps=200 * base.algo.env_steps_per_update)
programs = driver.programs_for(cfg)
state = programs.init(driver.seed_keys(cfg))
state, m = programs.chunk(state, jnp.int32(1)); jax.block_until_ready(m)
env("B after compile + 1 update")
t0 = time.time(); state, m = programs.chunk(state, jnp.int32(10)); jax.block_until_ready(m)
print(f"train 10 updates {10*base.algo.env_steps_per_update/(time.time()-t0):,.0f}", flush=True)
env("C after 10 updates")
env("C2 again")
time.sleep(10)
env("D after 10 s idle")
t0 = time.time(); state, m = programs.chunk(state, jnp.int32(10)); jax.block_until_ready(m)
print(f"train 10 updates {10*base.algo.env_steps_per_update/(time.time()-t0):,.0f}", flush=True)
env("E after 10 more updates")
fresh = jax.tree.map(jnp.copy, args); jax.block_until_ready(fresh)
env("F fresh copies of the env state", fresh)
env("F2 original buffers again")
del state, m; gc.collect()
env("G after the training state was freed")
for k in range(3):
    t0 = time.time(); x = jnp.ones((1 << 28,)) * 2; jax.block_until_ready(x); del x
    env(f"H{k} after a 1 GiB temp alloc")
t0 = time.time()
while time.time() - t0 < 8:
    y = jnp.sum(jnp.sin(jnp.ones((1 << 26,)))); jax.block_until_ready(y)
env("I after 8 s of other GPU work")
