"""One policy evaluated across the values of one env setting, with one compiled program where the setting allows it
(cross-evaluation tables: a policy trained on one obstacle size evaluated on others).

    from agents import evaluation, sweep
    policy = evaluation.checkpoint_policy("results/checkpoints/panda-reach-avoid-ppo")
    configs = [envs.make_config("panda-reach-avoid", policy.train_env_config, obstacle_radius=r) for r in (0.05, 0.2)]
    results = sweep.run(policy, "panda-reach-avoid", "obstacle_radius", configs)

`evaluation.run` compiles one program per env config, since every config value is a constant of its traced program:
tracing, lowering and loading it from the persistent cache cost seconds per setting. A field named in the config
class's `TRACED_FIELDS` (read by the env only inside its traced functions) is instead an argument of one program,
traced once per group of values that shape the program alike (the envs' candidate counts, `ArmEnv.candidate_counts`);
any other field falls back to `evaluation.run` per value. Same episodes and numbers as `evaluation.run` up to float
rounding (tests/test_sweep.py).
"""

from __future__ import annotations

import collections
import dataclasses
import functools
from typing import Callable

import jax
import numpy as np

import envs
from agents import evaluation


def traced(config, field: str) -> bool:
    """Whether `field` of an env config like `config` can be an argument of the evaluation program."""
    return field in getattr(type(config), "TRACED_FIELDS", ())


_PROGRAMS: collections.OrderedDict = collections.OrderedDict()
"""(env name, config without the field, field, shape key, network and evaluation options) -> (batched env, jitted
`evaluate(params, key, value)`, trained-seed counts it ran with); the most recently used last."""
PROGRAM_CACHE_SIZE = 16


def _traced_evaluator(env_name: str, env_config, field: str, env, policy: evaluation.Policy, num_envs: int,
                      last_steps: int, stochastic: bool) -> tuple:
    """The cached `(batched env, jitted evaluate(params, key, value), compiled set)` for configs like `env_config`
    (built as `env`) in every field but `field`, which the env reads from `value` (`ArmEnv.with_config`); what is
    decided at construction comes from `env_config`, alike for the configs sharing a key (`_shape_key`)."""
    e = policy.export
    sizes = (e.observation_size, e.action_size) if e else (0, 0)
    key = (env_name, dataclasses.replace(env_config, **{field: None}), field, _shape_key(env), policy.algo_config,
           sizes, num_envs, last_steps, stochastic, policy.planner)
    if key not in _PROGRAMS:
        base = env.unwrapped

        def evaluate(params, rng, value):
            traced_env = envs.wrap(base.with_config(dataclasses.replace(env_config, **{field: value})), autoreset=False)
            return evaluation.evaluate_fn(traced_env, policy.algo_config, *sizes, num_envs, env_config.episode_length,
                                          last_steps, stochastic, policy.planner)(params, rng)

        _PROGRAMS[key] = (envs.wrap(base, autoreset=False), jax.jit(evaluate), set())
        while len(_PROGRAMS) > PROGRAM_CACHE_SIZE:
            _PROGRAMS.popitem(last=False)
    _PROGRAMS.move_to_end(key)
    return _PROGRAMS[key]


def _shape_key(env) -> tuple:
    """What an env decides at construction from its config and a traced field may change (array shapes)."""
    return tuple(sorted(getattr(env.unwrapped, "candidate_counts", {}).items()))


def run(policy: evaluation.Policy, env_name: str, field: str, configs: list, num_envs: int = 4096,
        eval_seeds=(evaluation.DEFAULT_EVAL_SEED,), last_steps: int = 10, stochastic: bool = False,
        progress: Callable[[str], None] | None = None, allow_env_mismatch: bool = False) -> list[evaluation.Result]:
    """`evaluation.run(policy, env_name, config, ...)` for each of `configs`, which differ only in `field`: one
    `Result` per config, in order. Each config is checked as `evaluation.run` checks it before anything is evaluated."""
    if not configs:
        raise ValueError("configs=[] is invalid: allowed is at least one env config.")
    base = dataclasses.asdict(configs[0])
    for config in configs:
        other = [k for k, v in dataclasses.asdict(config).items() if k != field and v != base[k]]
        if other:
            raise ValueError(f"configs differ in {other} besides field={field!r}: allowed are configs differing only "
                             f"in {field!r}.")
    kw = dict(num_envs=num_envs, eval_seeds=eval_seeds, last_steps=last_steps, stochastic=stochastic,
              progress=progress, allow_env_mismatch=allow_env_mismatch)
    if not traced(configs[0], field):
        return [evaluation.run(policy, env_name, config, **kw) for config in configs]
    evaluation.check_request(policy, num_envs, eval_seeds, stochastic)
    built = []
    for config in configs:  # every value checked before any evaluation
        env = envs.from_config(env_name, config)
        evaluation.check_compatible(policy, env_name, env, allow_env_mismatch)
        built.append(env)
    results = []
    for config, env in zip(configs, built):
        batched, evaluate, compiled = _traced_evaluator(env_name, config, field, env, policy, int(num_envs),
                                                        int(last_steps), bool(stochastic))
        value = np.asarray(getattr(config, field), np.float32)
        program = evaluation.Program(batched, functools.partial(evaluate, value=value), compiled)
        results.append(evaluation.run_program(policy, program, env_name, config, int(num_envs), list(eval_seeds),
                                              int(last_steps), bool(stochastic), progress))
    return results
