"""Where a PPO update's time goes: the full compiled chunk timed next to variants that leave one
piece out or change one setting (METHOD: time variants, take differences).

    python benchmarks/ppo_breakdown.py --out results/ppo_breakdown     # on the GPU machine

Variants: `rollout only` replaces the learner's update by a no-op (env steps + policy sampling +
episode bookkeeping), `transitions kept` makes that no-op read the recorded transitions, `random
actions` also replaces the policy; the others change one PPOConfig field. `--env-only` adds the env
alone (random actions, no training loop) as the reference. Each row: env steps/s of `--updates`
updates after a compiling warm-up, and seconds per update.
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

import jax  # noqa: E402
import jax.numpy as jnp  # noqa: E402

import train as train_cli  # noqa: E402
from agents import driver  # noqa: E402
from agents.loop import env_random  # noqa: E402
from agents.ppo import PPO  # noqa: E402

sys.path.insert(0, str(ROOT / "benchmarks"))
from env_throughput import env_rate  # noqa: E402


class RolloutOnly(PPO):
    """PPO with its update replaced by a no-op: XLA drops the unused transitions, so this times env
    steps, policy sampling and episode bookkeeping."""

    def update(self, state, batch, key, par):
        return state, {"loss/none": jnp.zeros(())}


class RolloutKeep(PPO):
    """PPO whose update only reads every recorded transition (one sum), so they are stored."""

    def update(self, state, batch, key, par):
        return state, {"loss/none": sum(jnp.sum(x) for x in jax.tree.leaves(batch))}


class RandomActions(RolloutKeep):
    """As `RolloutKeep`, with uniform random actions instead of the policy network."""

    def act(self, state, obs, key, par):
        return env_random(key, par, (self.action_size,), "uniform"), {}


def seconds_per_update(config, updates, learner_cls=None):
    """Seconds per update of the config's compiled chunk; `learner_cls` (e.g. `RolloutOnly`) in
    place of PPO (`agents.driver.train`'s hook for modified learners)."""
    programs = driver.programs_for(config, learner_cls)
    state = programs.init(driver.seed_keys(config))
    state, metrics = programs.chunk(state, jnp.int32(0))  # compile
    jax.block_until_ready(metrics)
    start = time.perf_counter()
    state, metrics = programs.chunk(state, jnp.int32(updates))
    jax.block_until_ready(metrics)
    return (time.perf_counter() - start) / updates


def main():
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--preset", default="ur5e-reach-ppo")
    parser.add_argument("--updates", type=int, default=8)
    parser.add_argument("--variants", nargs="+", help="names of the variants to time (default: all)")
    parser.add_argument("--env-only", action="store_true", help="also time the env alone (benchmarks/env_throughput.py)")
    parser.add_argument("--out", default="results/ppo_breakdown")
    args = parser.parse_args()
    # One device, whatever the machine has (the default, devices=0, would split the envs over all).
    base = train_cli.make_config(args.preset, eval_envs=0, progress=False, tensorboard=False, num_timesteps=10**9,
                                 devices=1)
    algo = base.algo
    with_algo = lambda **kw: dataclasses.replace(base, algo=dataclasses.replace(algo, **kw))
    variants = {
        "full update": (base, None),
        "rollout only": (base, RolloutOnly),
        "rollout, transitions kept": (base, RolloutKeep),
        "rollout, random actions, transitions kept": (base, RandomActions),
        "no advantage recompute per epoch": (with_algo(recompute_advantages=False), None),
        "no value normalisation": (with_algo(normalize_value_targets=False), None),
        "no gradient clipping": (with_algo(max_grad_norm=0.0), None),
        "1 epoch instead of 5": (with_algo(updates_per_batch=1), None),
    }
    chosen = args.variants or list(variants)
    unknown = [v for v in chosen if v not in variants]
    if unknown:
        raise SystemExit(f"error: --variants {unknown} unknown: allowed are {', '.join(map(repr, variants))}")
    rows = []
    spu = algo.env_steps_per_update
    out = Path(args.out)
    out.parent.mkdir(parents=True, exist_ok=True)
    meta = {"device": jax.devices()[0].device_kind, "jax": jax.__version__, "date": datetime.date.today().isoformat(),
            "command": " ".join(["python"] + sys.argv), "preset": args.preset, "updates": args.updates}

    def record(name, seconds):  # written after every row, so a cut-off run keeps what it measured
        rows.append({"variant": name, "seconds_per_update": seconds, "env_steps_per_s": spu / seconds})
        print(f"{name:45s} {seconds * 1000:8.1f} ms/update {spu / seconds:12,.0f} env steps/s", flush=True)
        out.with_suffix(".json").write_text(json.dumps({"meta": meta, "rows": rows}, indent=2))

    if args.env_only:
        rate = env_rate(base.env_name, algo.num_envs, spu // algo.num_envs, 3, config=base.env)  # the trained env
        record("env only (random actions, no training loop)", spu / rate)
    for name in chosen:
        config, wrapper = variants[name]
        record(name, seconds_per_update(config, args.updates, wrapper))

if __name__ == "__main__":
    main()
