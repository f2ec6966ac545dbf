"""One policy evaluated across the values of one env setting, with one compiled program where the setting allows it
(cross-evaluation tables: a policy trained on one obstacle size evaluated on others).

    import envs
    from agents import evaluation, sweep
    policy = evaluation.checkpoint_policy("results/checkpoints/panda-reach-avoid-ppo")
    configs = [envs.make_config("panda-reach-avoid", policy.train_env_config, obstacle_radius=r) for r in (0.05, 0.2)]
    results = sweep.run(policy, "panda-reach-avoid", "obstacle_radius", configs)

`evaluation.run` compiles one program per env config, since every config value is a constant of its traced program:
tracing, lowering and loading it from the persistent cache cost seconds per setting. A field named in the config
class's `TRACED_FIELDS` (read by the env only inside its traced functions) is instead an argument of one program,
traced once per group of values that shape the program alike (`ArmEnv.program_key`); any other field falls back to
`evaluation.run` per value. Same episodes and numbers as `evaluation.run` up to float rounding (tests/test_sweep.py).
"""

from __future__ import annotations

import dataclasses
import functools
from typing import Callable

import jax
import numpy as np

import envs
from agents import evaluation
from envs.cache import LRU


def traced(config, field: str) -> bool:
    """Whether `field` of an env config like `config` can be an argument of the evaluation program."""
    return field in getattr(type(config), "TRACED_FIELDS", ())


@dataclasses.dataclass
class _Entry(evaluation.Program):
    """A cached program: `evaluation.Program` whose `evaluate(params, key, value)` takes the field's value, and how
    often it was traced (what tests/test_sweep.py counts)."""

    traces: int = 0


PROGRAM_CACHE_SIZE = 16
_PROGRAMS = LRU(PROGRAM_CACHE_SIZE)
"""(env name, config without the field, field, program key, network and evaluation options) -> `_Entry`."""


def _traced_evaluator(env_name: str, env_config, field: str, env, policy: evaluation.Policy, num_envs: int,
                      last_steps: int, stochastic: bool) -> _Entry:
    """The cached program for configs like `env_config` (built as `env`) in every field but `field`, which the env
    reads from `value` (`ArmEnv.with_config`); what is decided at construction comes from `env_config`, alike for the
    configs sharing a key (`ArmEnv.program_key`)."""
    e, algo_config, planner = policy.export, policy.algo_config, policy.planner  # not the params: kept while cached
    sizes = (e.observation_size, e.action_size) if e else (0, 0)
    base = env.unwrapped
    key = (env_name, dataclasses.replace(env_config, **{field: None}), field, base.program_key(), algo_config, sizes,
           num_envs, last_steps, stochastic, planner)

    def make() -> _Entry:
        entry = _Entry(envs.wrap(base, autoreset=False), None)

        def evaluate(params, rng, value):
            entry.traces += 1
            traced_env = envs.wrap(base.with_config(dataclasses.replace(env_config, **{field: value})), autoreset=False)
            return evaluation.evaluate_fn(traced_env, algo_config, *sizes, num_envs, env_config.episode_length,
                                          last_steps, stochastic, planner)(params, rng)

        entry.evaluate = jax.jit(evaluate)
        return entry

    return _PROGRAMS.get(key, make)


def check(env_name: str, field: str, configs: list) -> None:
    """ValueError unless `configs` are valid configs of `env_name` of one class that differ only in `field`, a field
    with an effect under them."""
    if not configs:
        raise ValueError("configs=[] is invalid: allowed is at least one env config.")
    kind = type(configs[0])
    names = [f.name for f in dataclasses.fields(kind)]
    if field not in names:
        raise ValueError(f"field={field!r} is invalid: allowed are the fields of {kind.__name__}: {', '.join(names)}.")
    for config in configs:
        if type(config) is not kind:
            raise ValueError(f"configs mix {kind.__name__} and {type(config).__name__}: allowed is one config class.")
        envs.registry.check_config(env_name, config)
        other = [k for k in names if k != field and getattr(config, k) != getattr(configs[0], k)]
        if other:
            raise ValueError(f"configs differ in {other} besides field={field!r}: allowed are configs differing only "
                             f"in {field!r}.")
        inert = getattr(config, "inert_fields", dict)().get(field)
        if inert:
            raise ValueError(f"field={field!r} is invalid here: it has no effect ({inert}); allowed is a field the "
                             "configs use.")


def run(policy: evaluation.Policy, env_name: str, field: str, configs: list, num_envs: int = 4096,
        eval_seeds=(evaluation.DEFAULT_EVAL_SEED,), last_steps: int = 10, stochastic: bool = False,
        progress: Callable[[str], None] | None = None, allow_env_mismatch: bool = False) -> list[evaluation.Result]:
    """`evaluation.run(policy, env_name, config, ...)` for each of `configs`, which differ only in `field`: one
    `Result` per config, in order. Every config is checked (`check`, and whether the policy can act in its env)
    before anything is evaluated."""
    check(env_name, field, configs)
    evaluation.check_request(policy, num_envs, eval_seeds, stochastic)
    built = []
    for config in configs:
        env = envs.registry.build(env_name, config)  # checked by `check`
        evaluation.check_compatible(policy, env_name, env, allow_env_mismatch)
        built.append(env)
    kw = dict(num_envs=num_envs, eval_seeds=eval_seeds, last_steps=last_steps, stochastic=stochastic,
              progress=progress, allow_env_mismatch=allow_env_mismatch)
    if not traced(configs[0], field):
        return [evaluation.run(policy, env_name, config, **kw) for config in configs]
    results = []
    for config, env in zip(configs, built):
        entry = _traced_evaluator(env_name, config, field, env, policy, int(num_envs), int(last_steps), bool(stochastic))
        value = np.asarray(getattr(config, field), np.float32)  # TRACED_FIELDS are floats
        program = evaluation.Program(entry.env, functools.partial(entry.evaluate, value=value), entry.compiled)
        results.append(evaluation.run_program(policy, program, env_name, config, int(num_envs), list(eval_seeds),
                                              int(last_steps), bool(stochastic), progress))
    return results
