"""Brax's PPO and ours on the same environment with the same hyperparameters and budget, in one run.

    python -m benchmarks.brax_reference --out results/throughput/brax_reference      # on the GPU machine

Both train on the preset's env (`--preset`, default `ur5e-reach-ppo`: the paper's configuration)
with the preset's PPO settings (`agents/presets.py`), which both learners get, observation
normalisation included. Ours adds its documented stability defaults (learning-rate decay, gradient
clipping, value normalisation). Brax runs with its own training wrappers, as a Brax user would (its
auto-reset restores each env's cached first state).

Both are scored by the same evaluator (`agents.loop.make_evaluate`): the deterministic policy on the
same `--eval-envs` freshly sampled episodes, at the same env-step counts. Training speed excludes
evaluation: ours times the compiled training chunks; Brax's is its own `training/sps` (median over
epochs after the first, which compiles). Results are written after every evaluation, so a cut-off
run keeps them. Brax is only a reference: this script is the one place outside tests that imports
it.
"""

from __future__ import annotations

import argparse
import datetime
import functools
import json
import statistics
import sys
import time
from pathlib import Path

import jax
import jax.numpy as jnp

import envs
from agents import driver, presets
from agents.loop import make_evaluate

if not hasattr(jax, "device_put_replicated"):
    # brax 0.14.2 still calls this; jax >= 0.10 removed it. Same result for our single-host use.
    jax.device_put_replicated = lambda x, devices: jax.device_put(
        jax.tree.map(lambda a: jnp.stack([jnp.asarray(a)] * len(devices)), x))

REPORTED = ("target_reached", "self_collision", "steps_in_target", "times_left_target", "distance_last10")


class BraxPolicy:
    """Adapts a Brax `make_policy` to the `policy(params, obs)` our evaluator calls."""

    def __init__(self, make_policy):
        self.make_policy = make_policy

    def policy(self, params, obs):
        return self.make_policy(params, deterministic=True)(obs, jax.random.PRNGKey(0))[0]


def summarize(metrics) -> dict:
    m = jax.device_get(metrics)
    return {name: float(jnp.mean(m[f"episode/{name}"])) for name in REPORTED}


def main():
    parser = argparse.ArgumentParser(prog="python -m benchmarks.brax_reference", description=__doc__.split("\n\n")[0])
    parser.add_argument("--preset", default="ur5e-reach-ppo")
    parser.add_argument("--evals", type=int, default=8, help="evaluations after the initial one")
    parser.add_argument("--updates-per-eval", type=int, default=16, help="PPO updates between evaluations")
    parser.add_argument("--eval-envs", type=int, default=4096)
    parser.add_argument("--skip", choices=["ours", "brax"], default=None)
    parser.add_argument("--out", default="results/throughput/brax_reference")
    args = parser.parse_args()

    config = presets.make_config(args.preset, eval_envs=args.eval_envs, progress=False, tensorboard=False)
    algo = config.algo
    spu = algo.env_steps_per_update
    total = args.evals * args.updates_per_eval * spu
    config = config.__class__(**{**config.__dict__, "num_timesteps": total})
    out = Path(args.out)
    out.parent.mkdir(parents=True, exist_ok=True)
    device = jax.devices()[0]
    command = " ".join(["python", "-m", "benchmarks.brax_reference"] + sys.argv[1:])
    report = {"meta": {"device": device.device_kind, "jax": jax.__version__, "date": datetime.date.today().isoformat(),
                       "command": command, "preset": args.preset, "env_name": config.env_name,
                       "num_timesteps": total, "eval_envs": args.eval_envs},
              "ours": {"evals": []}, "brax": {"evals": []}}

    def save():
        out.with_suffix(".json").write_text(json.dumps(report, indent=2))

    env = envs.from_config(config.env_name, config.env)
    batched = envs.wrap(env)
    eval_key = jax.random.PRNGKey(config.eval_seed)

    if args.skip != "ours":
        programs = driver.programs_for(config)
        state = programs.init(driver.seed_keys(config))
        # The update count is traced: a zero-update chunk compiles the program without training.
        start = time.perf_counter()
        state, metrics = programs.chunk(state, jnp.int32(0))
        jax.block_until_ready(metrics)
        report["ours"]["compile_seconds"] = time.perf_counter() - start
        train_seconds = 0.0
        for i in range(args.evals + 1):
            if i:
                start = time.perf_counter()
                state, metrics = programs.chunk(state, jnp.int32(args.updates_per_eval))
                jax.block_until_ready(metrics)
                train_seconds += time.perf_counter() - start
            steps = int(jax.device_get(state.updates[0])) * spu
            row = {"env_steps": steps, **summarize(programs.evaluate(state.learner, eval_key))}
            report["ours"]["evals"].append(row)
            print("ours", row, flush=True)
            save()
        report["ours"]["steps_per_s"] = total / train_seconds
        save()

    if args.skip != "brax":
        from brax.training.agents.ppo import networks as brax_networks
        from brax.training.agents.ppo import train as brax_ppo

        evaluate = None
        sps = []

        def on_params(step, make_policy, params):
            nonlocal evaluate
            if evaluate is None:
                evaluate = jax.jit(make_evaluate(batched, BraxPolicy(make_policy), args.eval_envs,
                                                 config.env.episode_length))
            row = {"env_steps": int(step), **summarize(evaluate(params, eval_key))}
            report["brax"]["evals"].append(row)
            print("brax", row, flush=True)
            save()

        def on_progress(step, metrics):
            if "training/sps" in metrics:
                sps.append(float(metrics["training/sps"]))
                report["brax"]["sps_per_epoch"] = sps
                save()

        hidden = algo.policy_hidden_sizes
        brax_ppo.train(
            environment=env, num_timesteps=total, num_evals=args.evals + 1, episode_length=config.env.episode_length,
            num_envs=algo.num_envs, batch_size=algo.batch_size, num_minibatches=algo.num_minibatches,
            unroll_length=algo.unroll_length, num_updates_per_batch=algo.updates_per_batch,
            learning_rate=algo.learning_rate, discounting=algo.discount, entropy_cost=algo.entropy_coef,
            gae_lambda=algo.gae_lambda, clipping_epsilon=algo.clip_epsilon, normalize_observations=True,
            reward_scaling=algo.reward_scaling, num_eval_envs=128, seed=config.seed,
            network_factory=functools.partial(brax_networks.make_ppo_networks, policy_hidden_layer_sizes=hidden,
                                              value_hidden_layer_sizes=algo.value_hidden_sizes),
            policy_params_fn=on_params, progress_fn=on_progress,
        )
        report["brax"]["steps_per_s"] = statistics.median(sps[1:]) if len(sps) > 1 else (sps[0] if sps else None)
        save()

    ours, brax = report["ours"].get("steps_per_s"), report["brax"].get("steps_per_s")
    if ours and brax:
        report["speedup"] = ours / brax
    save()
    lines = [f"# Brax PPO vs ours on {config.env_name} ({report['meta']['device']}, {report['meta']['date']})", "",
             f"Command: `{report['meta']['command']}`; jax {jax.__version__}; the preset's hyperparameters; both evaluated by "
             f"`agents.loop.make_evaluate` on the same {args.eval_envs} fresh episodes (deterministic policy).", "",
             f"Training env steps/s: ours {ours or float('nan'):,.0f}, Brax {brax or float('nan'):,.0f}"
             + (f", ratio {report['speedup']:.2f}x" if "speedup" in report else "") + ".", "",
             "| env steps | ours: reached | ours: self coll. | ours: steps in target | Brax: reached | Brax: self coll. | Brax: steps in target |",
             "|---:|---:|---:|---:|---:|---:|---:|"]
    by_step = {}
    for who in ("ours", "brax"):
        for row in report[who]["evals"]:
            by_step.setdefault(row["env_steps"], {})[who] = row
    for steps in sorted(by_step):
        cells = []
        for who in ("ours", "brax"):
            r = by_step[steps].get(who)
            cells += [f"{r['target_reached']:.3f}", f"{r['self_collision']:.3f}", f"{r['steps_in_target']:.1f}"] if r else ["", "", ""]
        lines.append(f"| {steps:,} | " + " | ".join(cells) + " |")
    out.with_suffix(".md").write_text("\n".join(lines) + "\n")
    print("\n".join(lines))


if __name__ == "__main__":
    main()
