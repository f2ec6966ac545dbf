"""Whether a policy can act in an env: the same robot, observation and action sizes, the trained observation layout
and action mode, and no observed part at a value it never saw in training (`agents.evaluation` checks every
evaluation with these; `policy` is an `agents.evaluation.Policy`)."""

from __future__ import annotations

import warnings

import envs
from agents import baselines


def check(policy, env_name: str, env_config, allow_env_mismatch: bool = False) -> None:
    """The env config's own checks, then `check_compatible` on the env built from it (cheap: nothing is
    compiled)."""
    check_compatible(policy, env_name, envs.from_config(env_name, env_config), allow_env_mismatch)


LAYOUT_FIELDS = ("observation", "action")
"""Env options a network is tied to beyond the sizes: the order of the observation's parts and the
meaning of its action (relative steps or absolute joint targets)."""


def unseen_constants(trained_config, asked_config) -> list[str]:
    """Observed parts that held one value in every training episode (`constant_observations` of the env config)
    but vary, or hold another value, under `asked_config`. The network never saw them change, and its
    observation normaliser, fit to one value (variance 0), divides any other by ~1e-4 and clips it: a static
    agent evaluated on moving obstacles while observing their velocity reached 0 % where it reached 80 % on
    static ones (results/experiments/obstacles-moving3)."""
    trained = getattr(trained_config, "constant_observations", dict)()
    asked = getattr(asked_config, "constant_observations", dict)()
    observed = getattr(trained_config, "observation", ())
    return [f"{part} (trained with {why}, here {asked.get(part, 'varying')})" for part, why in trained.items()
            if part in observed and asked.get(part) != why]


def check_compatible(policy, env_name: str, env, allow_env_mismatch: bool = False) -> None:
    """ValueError unless `policy` can act in `env` (same robot, matching observation and action
    sizes, and the trained observation layout and action mode; with `allow_env_mismatch` a different
    layout or mode is only warned about)."""
    if policy.export is None:
        if policy.planner is None:  # the planner acts on any env: it simulates the env itself
            baselines.check(policy.name, env)
        return
    e = policy.export
    trained, asked = envs.registry.spec(e.env_name).robot, envs.registry.spec(env_name).robot
    if trained != asked:
        allowed = f"the envs of robot {trained}" if trained else "the envs without a robot"
        raise ValueError(f"checkpoint {policy.name!r} was trained on {e.env_name!r} (robot {trained or 'none'}): "
                         f"env={env_name!r} is another robot; allowed are {allowed}.")
    config = getattr(env.unwrapped, "config", None)
    if env.observation_size != e.observation_size:
        observation = getattr(config, "observation", None)
        shown = f" with observation={observation!r}" if observation is not None else ""
        trained_obs = getattr(e.config.env, "observation", None)
        allowed = (f"the trained observation {trained_obs!r}" if trained_obs is not None
                   else f"observations of shape ({e.observation_size},), as trained")
        raise ValueError(f"the network of checkpoint {policy.name!r} takes observations of shape ({e.observation_size},) but "
                         f"env {env_name!r}{shown} gives shape ({env.observation_size},): allowed are env options giving "
                         f"{allowed}.")
    if env.action_size != e.action_size:
        raise ValueError(f"the network of checkpoint {policy.name!r} outputs actions of shape ({e.action_size},) but env "
                         f"{env_name!r} takes shape ({env.action_size},).")
    differ = [f"{name}={getattr(config, name)!r} (trained: {getattr(e.config.env, name)!r})" for name in LAYOUT_FIELDS
              if hasattr(config, name) and hasattr(e.config.env, name)
              and getattr(config, name) != getattr(e.config.env, name)]
    if differ:
        _mismatch(allow_env_mismatch,
                  f"checkpoint {policy.name!r} is evaluated with {'; '.join(differ)}: its network reads and acts as "
                  "trained, so the numbers describe a mismatched policy (allowed by allow_env_mismatch).",
                  f"checkpoint {policy.name!r} cannot run with {'; '.join(differ)}: its network reads the observation's "
                  "parts in the trained order and its actions in the trained mode; allowed are the trained values")
    unseen = unseen_constants(policy.train_env_config, config)
    if unseen:
        _mismatch(allow_env_mismatch,
                  f"checkpoint {policy.name!r} observes {'; '.join(unseen)}: a value it never saw in training, which "
                  "its observation normaliser scales to the clip (allowed by allow_env_mismatch).",
                  f"checkpoint {policy.name!r} cannot be evaluated fairly here: it observes {'; '.join(unseen)}. It saw "
                  "one value of each in training, and its observation normaliser scales any other to the clip; "
                  "allowed are the trained settings of those parts, or a policy trained without them in its observation")


def _mismatch(allowed: bool, warning: str, refusal: str) -> None:
    """Warns (the user asked for the mismatch: `allow_env_mismatch`) or raises, naming the escape hatch."""
    if allowed:
        warnings.warn(warning, stacklevel=4)
    else:
        raise ValueError(refusal + " (or --allow-env-mismatch to evaluate anyway, with a warning).")
