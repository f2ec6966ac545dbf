"""Where a PPO update's time goes: the full compiled chunk timed next to variants that leave one
piece out or change one setting (METHOD: time variants, take differences).

    python benchmarks/ppo_breakdown.py --out results/ppo_breakdown     # on the GPU machine

Variants: `rollout only` replaces the learner's update by a no-op (env steps + policy sampling +
episode bookkeeping); the others change one PPOConfig / env field. Each row: env steps/s of
`--updates` updates after a compiling warm-up, and seconds per update.
"""

from __future__ import annotations

import argparse
import dataclasses
import json
import sys
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

import jax  # noqa: E402
import jax.numpy as jnp  # noqa: E402

import envs  # noqa: E402
import train as train_cli  # noqa: E402
from agents import driver  # noqa: E402
from agents.loop import Programs  # noqa: E402


class RolloutOnly:
    """The PPO learner with its update replaced by a no-op."""

    def __init__(self, learner):
        self.inner = learner
        self.steps_per_update = learner.steps_per_update

    def __getattr__(self, name):
        return getattr(self.inner, name)

    def update(self, state, batch, key, par):
        return state, {"loss/none": jnp.zeros(())}


def seconds_per_update(config, updates, rollout_only=False):
    if rollout_only:
        env = envs.wrap(envs.from_config(config.env_name, config.env))
        learner = RolloutOnly(driver.make_learner(config.algo, env.observation_size, env.action_size, updates))
        programs = Programs(env, env, learner, config.algo.num_envs, config.seeds, jax.local_devices()[:1], 1,
                            config.env.episode_length)
    else:
        programs = driver.programs_for(config)
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
    parser.add_argument("--out", default="results/ppo_breakdown")
    args = parser.parse_args()
    base = train_cli.make_config(args.preset, eval_envs=0, progress=False, tensorboard=False, num_timesteps=10**9)
    algo, env = base.algo, base.env
    variants = [
        ("full update", base, False),
        ("rollout only", base, True),
        ("no advantage recompute per epoch", dataclasses.replace(base, algo=dataclasses.replace(algo, recompute_advantages=False)), False),
        ("no value normalisation", dataclasses.replace(base, algo=dataclasses.replace(algo, normalize_value_targets=False)), False),
        ("no gradient clipping", dataclasses.replace(base, algo=dataclasses.replace(algo, max_grad_norm=0.0)), False),
        ("1 epoch instead of 5", dataclasses.replace(base, algo=dataclasses.replace(algo, updates_per_batch=1)), False),
        ("8 sampling candidates", dataclasses.replace(base, env=dataclasses.replace(env, sampling_candidates=8)), False),
        ("rollout only, 8 candidates", dataclasses.replace(base, env=dataclasses.replace(env, sampling_candidates=8)), True),
    ]
    rows = []
    spu = algo.env_steps_per_update
    for name, config, rollout_only in variants:
        s = seconds_per_update(config, args.updates, rollout_only)
        rows.append({"variant": name, "seconds_per_update": s, "env_steps_per_s": spu / s})
        print(f"{name:40s} {s * 1000:8.1f} ms/update {spu / s:12,.0f} env steps/s", flush=True)
    out = Path(args.out)
    out.parent.mkdir(parents=True, exist_ok=True)
    meta = {"device": jax.devices()[0].device_kind, "jax": jax.__version__, "command": " ".join(["python"] + sys.argv)}
    out.with_suffix(".json").write_text(json.dumps({"meta": meta, "rows": rows}, indent=2))


if __name__ == "__main__":
    main()
