"""Brax's PPO or SAC and ours on the same environment with the same hyperparameters and budget, in one run.

    python -m benchmarks.brax_reference --out results/throughput/brax_reference                  # PPO, on the GPU
    python -m benchmarks.brax_reference --preset ur5e-reach-sac --out results/sac/brax_reference  # SAC (paper settings)

Both train on the preset's env (`--preset`, default `ur5e-reach-ppo`: the paper's configuration)
with the preset's settings (`agents/presets.py`), which both learners get, observation
normalisation included. Ours adds its documented defaults (PPO: learning-rate decay, gradient
clipping, value normalisation). Brax runs with its own training wrappers, as a Brax user would (its
auto-reset restores each env's cached first state). Brax has neither n-step returns nor a categorical
critic, so the SAC comparison takes presets without them (the paper's `-sac` presets).

Both are scored by the same evaluator (`agents.loop.make_evaluate`): the deterministic policy on the
same `--eval-envs` freshly sampled episodes, at the same env-step counts (Brax's SAC exposes its
parameters only at the end, so it is scored once, at its last step). Training speed excludes
evaluation: ours times the compiled training chunks; Brax's is its own `training/sps` (median over
epochs after the first, which compiles). Results are written after every evaluation, so a cut-off
run keeps them. Brax is only a reference: this script is the one place outside tests that imports
it.
"""

from __future__ import annotations

import argparse
import contextlib
import dataclasses
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
from agents import driver, presets, provenance, registry
from agents.config import validate
from agents.loop import make_evaluate
from benchmarks.train_throughput import trace_chunk

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
    return {name: float(jnp.mean(m[f"episode/{name}"])) for name in REPORTED if f"episode/{name}" in m}


def brax_ppo(config, env, total, num_evals, on_params, on_progress):
    """Brax's PPO with the preset's PPO settings; `on_params` scores every evaluation's parameters."""
    from brax.training.agents.ppo import networks as brax_networks
    from brax.training.agents.ppo import train as brax_train

    algo = config.algo
    brax_train.train(
        environment=env, num_timesteps=total, num_evals=num_evals, episode_length=config.env.episode_length,
        num_envs=algo.num_envs, batch_size=algo.batch_size, num_minibatches=algo.num_minibatches,
        unroll_length=algo.unroll_length, num_updates_per_batch=algo.updates_per_batch,
        learning_rate=algo.learning_rate, discounting=algo.discount, entropy_cost=algo.entropy_coef,
        gae_lambda=algo.gae_lambda, clipping_epsilon=algo.clip_epsilon, normalize_observations=True,
        reward_scaling=algo.reward_scaling, num_eval_envs=128, seed=config.seed,
        network_factory=functools.partial(brax_networks.make_ppo_networks, policy_hidden_layer_sizes=algo.policy_hidden_sizes,
                                          value_hidden_layer_sizes=algo.value_hidden_sizes),
        policy_params_fn=on_params, progress_fn=on_progress,
    )


def brax_sac(config, env, total, num_evals, on_params, on_progress):
    """Brax's SAC with the preset's SAC settings (one hidden-layer list for actor and critics, as Brax
    has); its parameters are scored once, at the end."""
    from brax.envs import training as brax_wrappers
    from brax.training.agents.sac import networks as brax_networks
    from brax.training.agents.sac import train as brax_train

    algo = config.algo
    last = {"step": 0}
    progress = lambda step, metrics: (last.update(step=step), on_progress(step, metrics))  # noqa: E731
    make_policy, params, _ = brax_train.train(
        environment=env, num_timesteps=total, num_evals=num_evals, episode_length=config.env.episode_length,
        num_envs=algo.num_envs, batch_size=algo.batch_size, learning_rate=algo.learning_rate,
        discounting=algo.discount, reward_scaling=algo.reward_scaling, tau=algo.tau,
        min_replay_size=algo.min_replay_size, max_replay_size=algo.max_replay_size,
        grad_updates_per_step=algo.grad_updates_per_step, normalize_observations=algo.normalize_observations,
        num_eval_envs=128, seed=config.seed, deterministic_eval=True,
        wrap_env_fn=brax_wrappers.wrap,  # the wrappers Brax's PPO applies; its SAC checks for a Brax Env class instead
        network_factory=functools.partial(brax_networks.make_sac_networks, hidden_layer_sizes=algo.q_hidden_sizes,
                                          activation=getattr(jax.nn, algo.activation),
                                          policy_network_layer_norm=algo.layer_norm, q_network_layer_norm=algo.layer_norm),
        progress_fn=progress,
    )
    on_params(last["step"], make_policy, params)


def brax_sac_epochs(total: int, num_envs: int, min_replay_size: int, num_evals: int) -> tuple[int, int]:
    """(prefill vector steps, training vector steps per epoch) of Brax's SAC run with `num_timesteps=total`: it
    prefills ceil(min_replay_size / num_envs) vector steps, counted in the budget, then splits the rest over
    max(num_evals - 1, 1) epochs (`brax.training.agents.sac.train`), so an epoch is shorter than ours."""
    prefill = -(-min_replay_size // num_envs)
    return prefill, -(-(total - prefill * num_envs) // (max(num_evals - 1, 1) * num_envs))


class EpochTrace:
    """Profiles Brax's second training epoch alone (its first compiles): from Brax's second progress call to
    the start of the next evaluation, Brax's evaluator or ours of the epoch's parameters, whichever comes
    first, so that no evaluation's kernels fall in the trace."""

    def __init__(self, directory: str, start_trace=None, stop_trace=None):
        self.directory = directory
        self.start_trace = start_trace or (lambda d: jax.profiler.start_trace(d, create_perfetto_trace=True))
        self.stop_trace = stop_trace or jax.profiler.stop_trace
        self.on = False

    def progress(self, calls: int):
        """Brax's progress_fn was called for the `calls`-th time (the first at step 0, then after each epoch
        and its evaluations)."""
        if calls == 2:
            self.start_trace(self.directory)
            self.on = True
        elif calls > 2:
            self.stop()

    def stop(self):
        """An evaluation starts (or Brax's progress comes): end the trace if it runs."""
        if self.on:
            self.stop_trace()
            self.on = False


@contextlib.contextmanager
def before_brax_evaluations(hook):
    """Calls `hook()` at the start of each of Brax's own evaluations (`acting.Evaluator.run_evaluation`,
    which its PPO and SAC run after every training epoch) while the context lasts."""
    from brax.training import acting

    original = acting.Evaluator.run_evaluation

    def run_evaluation(self, *args, **kwargs):
        hook()
        return original(self, *args, **kwargs)

    acting.Evaluator.run_evaluation = run_evaluation
    try:
        yield
    finally:
        acting.Evaluator.run_evaluation = original


BRAX_TRAINERS = {"ppo": brax_ppo, "sac": brax_sac}
"""Registered algorithm name -> the function that trains Brax's version of it on our env."""

DEFAULT_UPDATES_PER_EVAL = {"ppo": 16, "sac": 8192}
"""Updates between evaluations when --updates-per-eval is not given (SAC: vector steps of num_envs)."""

UNLIKE_BRAX = {"sac": {"n_step": 1, "distributional": False, "max_grad_norm": 0.0, "init_alpha": 1.0}}
"""Our options Brax's learner lacks, with the values under which both run the same algorithm."""


def brax_comparable(config, algo_name: str, action_size: int):
    """`config` with ours set as Brax's learner runs (SAC: Brax's target entropy -action_size / 2,
    where ours defaults to -action_size, and no clipping of normalised observations); a ValueError for
    options Brax cannot match."""
    algo = config.algo
    unlike = [f"algo.{k}={getattr(algo, k)!r}" for k, v in UNLIKE_BRAX.get(algo_name, {}).items() if getattr(algo, k) != v]
    if algo_name == "sac" and algo.policy_hidden_sizes != algo.q_hidden_sizes:
        unlike.append(f"algo.q_hidden_sizes={algo.q_hidden_sizes} != algo.policy_hidden_sizes={algo.policy_hidden_sizes}")
    if unlike:
        raise ValueError(f"the preset sets {', '.join(unlike)}, which Brax's {algo_name} cannot match: allowed are "
                         f"{UNLIKE_BRAX.get(algo_name, {})} and (SAC) one hidden-layer list for actor and critics.")
    if algo_name == "sac":  # Brax's SAC also normalises observations without clipping them
        return dataclasses.replace(config, algo=dataclasses.replace(algo, target_entropy=-0.5 * action_size, obs_clip=0.0))
    return config


def main(argv=None):
    parser = argparse.ArgumentParser(prog="python -m benchmarks.brax_reference", description=__doc__.split("\n\n")[0])
    parser.add_argument("--preset", default="ur5e-reach-ppo")
    parser.add_argument("--evals", type=int, default=8, help="evaluations after the initial one")
    parser.add_argument("--updates-per-eval", type=int, default=None,
                        help="updates between evaluations (default: 16 for PPO, 8,192 vector steps for SAC)")
    parser.add_argument("--eval-envs", type=int, default=4096)
    parser.add_argument("--skip", choices=["ours", "brax"], default=None)
    parser.add_argument("--out", default="results/throughput/brax_reference")
    parser.add_argument("--trace", metavar="DIR", help="also write profiler traces of one evaluation period of "
                        "training (--updates-per-eval updates) to DIR/ours (after the timed training, with the "
                        "program's HLO) and DIR/brax (its second training epoch, stopped when an evaluation starts; "
                        "Brax's SAC epochs are shorter: it spends ceil(min_replay_size / num_envs) vector steps of the "
                        "budget on its prefill first, then splits the rest over --evals epochs): "
                        "`python -m benchmarks.trace_summary DIR/ours`")
    args = parser.parse_args(argv)
    for flag, value in (("--evals", args.evals), ("--updates-per-eval", args.updates_per_eval),
                        ("--eval-envs", args.eval_envs)):
        if value is not None and value < 1:
            raise ValueError(f"{flag}={value} is invalid: allowed is an integer >= 1.")
    if args.trace and args.skip != "brax" and args.evals < 2:
        raise ValueError(f"--evals={args.evals} with --trace: allowed is 2 or more (Brax's second training epoch is "
                         "traced; its first compiles).")

    config = presets.make_config(args.preset, eval_envs=args.eval_envs, progress=False, tensorboard=False)
    algo_name = registry.of_config(config.algo).name
    if algo_name not in BRAX_TRAINERS:
        raise ValueError(f"--preset {args.preset} trains {algo_name}: allowed are presets of {', '.join(BRAX_TRAINERS)}.")
    spu = config.algo.env_steps_per_update
    updates_per_eval = args.updates_per_eval or DEFAULT_UPDATES_PER_EVAL[algo_name]
    total = args.evals * updates_per_eval * spu
    # Brax's SAC: (prefill vector steps, training vector steps per epoch); SAC's update is one vector step.
    brax_epochs = (brax_sac_epochs(total, spu, config.algo.min_replay_size, args.evals + 1)
                   if algo_name == "sac" else None)
    if brax_epochs and args.skip != "brax" and total <= brax_epochs[0] * spu:
        raise ValueError(f"--evals={args.evals} x --updates-per-eval={updates_per_eval} x {spu} env steps = {total:,} "
                         f"env steps is invalid for SAC: allowed is more than algo.min_replay_size="
                         f"{config.algo.min_replay_size:,} in whole vector steps ({brax_epochs[0] * spu:,}; Brax's SAC "
                         "trains only after its buffer holds that many).")
    env = envs.from_config(config.env_name, config.env)
    config = brax_comparable(config, algo_name, env.action_size)
    config = config.__class__(**{**config.__dict__, "num_timesteps": total})
    validate(config)  # every field before anything compiles
    out = Path(args.out)
    out.parent.mkdir(parents=True, exist_ok=True)
    device = jax.devices()[0]
    command = " ".join(["python", "-m", "benchmarks.brax_reference"] + (sys.argv[1:] if argv is None else list(argv)))
    report = {"meta": {"device": device.device_kind, "jax": jax.__version__, "date": datetime.date.today().isoformat(),
                       "command": command, "code": provenance.code_version(), "preset": args.preset,
                       "env_name": config.env_name, "num_timesteps": total, "eval_envs": args.eval_envs,
                       "algo": dataclasses.asdict(config.algo)},
              "ours": {"evals": []}, "brax": {"evals": []}}

    def save():
        out.with_suffix(".json").write_text(json.dumps(report, indent=2))

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
                state, metrics = programs.chunk(state, jnp.int32(updates_per_eval))
                jax.block_until_ready(metrics)
                train_seconds += time.perf_counter() - start
            steps = int(jax.device_get(state.updates[0])) * spu
            row = {"env_steps": steps, **summarize(programs.evaluate(state.learner, eval_key))}
            report["ours"]["evals"].append(row)
            print("ours", row, flush=True)
            save()
        report["ours"]["steps_per_s"] = total / train_seconds
        save()
        if args.trace:
            trace_dir = str(Path(args.trace) / "ours")
            state = trace_chunk(programs, state, updates_per_eval, trace_dir)
            report["ours"]["trace"] = {"dir": trace_dir, "vector_steps": updates_per_eval}
            save()

    if args.skip != "brax":
        evaluate = None
        sps = []

        trace = EpochTrace(str(Path(args.trace) / "brax")) if args.trace else None

        def on_params(step, make_policy, params):
            nonlocal evaluate
            if trace:
                trace.stop()
            if evaluate is None:
                evaluate = jax.jit(make_evaluate(batched, BraxPolicy(make_policy), args.eval_envs,
                                                 config.env.episode_length))
            row = {"env_steps": int(step), **summarize(evaluate(params, eval_key))}
            report["brax"]["evals"].append(row)
            print("brax", row, flush=True)
            save()

        progress_calls = []

        def on_progress(step, metrics):
            # Brax calls this at step 0, then after each training epoch: trace the second epoch (the first compiles).
            progress_calls.append(int(step))
            if trace:
                trace.progress(len(progress_calls))
                if len(progress_calls) == 3:
                    report["brax"]["trace"] = {
                        "dir": trace.directory, "what": "its second training epoch, without evaluations",
                        "vector_steps": (progress_calls[2] - progress_calls[1]) // config.algo.num_envs}
            report["brax"]["last_step"] = int(step)
            if "training/sps" in metrics:
                sps.append(float(metrics["training/sps"]))
                report["brax"]["sps_per_epoch"] = sps
                save()

        if brax_epochs:
            prefill, epoch = brax_epochs
            report["brax"].update(prefill_vector_steps=prefill, epoch_vector_steps=epoch)
            print(f"Brax's SAC: {prefill:,} prefill vector steps, then {args.evals} epochs of {epoch:,} vector steps "
                  f"(ours: {updates_per_eval:,} vector steps between evaluations, its warm-up inside them)", flush=True)
        with before_brax_evaluations(trace.stop if trace else lambda: None):
            BRAX_TRAINERS[algo_name](config, env, total, args.evals + 1, on_params, on_progress)
        report["brax"]["steps_per_s"] = statistics.median(sps[1:]) if len(sps) > 1 else (sps[0] if sps else None)
        save()

    ours, brax = report["ours"].get("steps_per_s"), report["brax"].get("steps_per_s")
    if ours and brax:
        report["speedup"] = ours / brax
    save()
    lines = [f"# Brax {algo_name.upper()} vs ours on {config.env_name} ({report['meta']['device']}, {report['meta']['date']})", "",
             f"Command: `{report['meta']['command']}`; jax {jax.__version__}; the preset's hyperparameters"
             + (f" (SAC's target entropy {config.algo.target_entropy:g}, Brax's -|A|/2, and no observation clipping, for both)"
                if algo_name == "sac" else "")
             + "; both evaluated by "
             f"`agents.loop.make_evaluate` on the same {args.eval_envs} fresh episodes (deterministic policy).", "",
             "Training env steps/s: " + ", ".join(
                 f"{who} " + (f"{speed:,.0f}" if speed else "not run (--skip)" if args.skip == who.lower() else "not measured")
                 for who, speed in (("ours", ours), ("Brax", brax)))
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
            cells += [f"{r.get(k, float('nan')):{f}}" for k, f in (("target_reached", ".3f"), ("self_collision", ".3f"),
                                                                ("steps_in_target", ".1f"))] if r else ["", "", ""]
        lines.append(f"| {steps:,} | " + " | ".join(cells) + " |")
    out.with_suffix(".md").write_text("\n".join(lines) + "\n")
    print("\n".join(lines))


if __name__ == "__main__":
    main()
