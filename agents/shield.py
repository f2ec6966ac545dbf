"""A trained policy shielded by the planner's model: the policy acts unless its own rollout in the model collides.

At every control step the shield copies each env's state and rolls the policy's deterministic actions `horizon`
steps ahead through the very same `env.step` (`agents.planner`'s model: it knows the obstacles' future motion).
If that rollout collides (a step with `self_collision` or `obstacle_collision`, before the simulated episode ends),
the executed action is instead the first of the best-return sampled sequence that the model shows clear, sampled
around the policy's own action sequence with the planner's options (`safest`); otherwise it is the policy's action,
unchanged. On a step the shield leaves alone the agent acts exactly as unshielded, so the shield tells whether reach
and safety can be had together by an agent overruled only where its own plan would collide (not in the paper: a
reference with a compute cost, `model_steps_per_step`).

`make_unit_act(env, learner, config)` returns the per-trained-seed action function and memory that
`agents.loop.make_evaluate_stacked` takes (`unit_act`, `unit_memory`, with `memory_metrics` for the count of steps
overruled); eval.py evaluates it with `--checkpoint PATH --shield`.
"""

from __future__ import annotations

from typing import NamedTuple

import jax
import jax.numpy as jnp

from agents import planner as planners
from agents.planner import PlannerConfig
from envs.wrappers import VmapWrapper


class Backup(NamedTuple):
    """The shield's memory for one env across steps."""

    plan: jax.Array
    """(H, A): the sequence chosen on the last overruled step, moved on a step."""
    active: jax.Array
    """Whether the last step was overruled: the next search starts from `plan`."""
    overruled: jax.Array
    """The steps overruled so far (`memory_metrics`)."""


def model_steps_per_step(config: PlannerConfig) -> int:
    """Env steps simulated in the model per executed step: the policy's rollout plus the planner's samples (under
    `vmap` both are computed on every step, whichever acts)."""
    return config.horizon + config.model_steps_per_step


def policy_rollout(step, policy_fn, state, horizon: int):
    """`(actions (H, A), fails)`: the deterministic `policy_fn(obs) -> action` rolled `horizon` steps from one env
    `state` by the single-env `step`; `fails` is True if a step collides before the simulated episode ends."""

    def advance(loop, _):
        s, fails, alive = loop
        action = policy_fn(s.obs)
        s = step(s, action)
        fails = fails | (alive & planners.failed(s))
        alive = alive & (s.done == 0)
        return (s, fails, alive), action

    (_, fails, _), actions = jax.lax.scan(advance, (state, jnp.zeros((), bool), jnp.ones((), bool)), None,
                                          length=horizon)
    return actions, fails


def safest(step, state, plan, key, config: PlannerConfig):
    """One sampling iteration of the fallback for one env: `samples` sequences, `plan` `(H, A)` unperturbed and the
    rest sampled around it, simulated; returns the best-return sequence among those that do not collide (if none is
    clear, the best-return one). The best verified sequence rather than MPPI's
    weighted mean, which can collide where none of the samples it averages does."""
    noise = config.noise * jax.random.normal(key, (config.samples,) + plan.shape)
    candidates = jnp.clip(plan[None] + noise.at[0].set(0.0), -1.0, 1.0)
    returns, fails = planners.sequence_outcomes(step, state, candidates, config.discount)
    score = returns - fails * (1.0 + jnp.max(returns) - jnp.min(returns))  # every clear one above every failing one
    return candidates[jnp.argmax(score)]


def shield_one(step, policy_fn, state, key, backup, config: PlannerConfig):
    """`(action, overruled, backup)` for one env: the policy's action while its rollout is clear, else the first
    action of the sequence `safest` picks, searched `iterations` times around the previous step's `backup` (its
    chosen sequence moved on a step) if that step was overruled, else around the policy's sequence: a plan found
    clear is followed on, rather than searched for anew from the policy's failing one each step. The backup also
    counts the steps overruled so far (`memory_metrics`)."""
    actions, fails = policy_rollout(step, policy_fn, state, config.horizon)
    around = jnp.where(backup.active, backup.plan, actions)
    plan, _ = jax.lax.scan(lambda p, k: (safest(step, state, p, k, config), None), around,
                           jax.random.split(key, config.iterations))
    action = jnp.where(fails, plan[0], actions[0])
    return action, fails, Backup(jnp.concatenate([plan[1:], plan[-1:]]), fails, backup.overruled + fails)


def no_backup(state, config: PlannerConfig, action_size: int):
    """The shield's memory for one env at an episode's start: no backup sequence, no step overruled."""
    return Backup(jnp.zeros((config.horizon, action_size)), jnp.zeros((), bool), jnp.zeros((), jnp.float32))


def memory_metrics(backups) -> dict:
    """`{"overruled_steps": ...}`: how many of each env's executed steps so far were not the policy's; at an episode's
    end over its length, the share of the episode the shield acted in."""
    return {"overruled_steps": backups.overruled}


def make_unit_act(env, learner, config: PlannerConfig):
    """`(unit_act, unit_memory)` for `make_evaluate_stacked` over the batched, non-resetting evaluation env `env`
    (`envs.wrap(..., autoreset=False)`): `unit_act(params, states, key, backups) -> (actions, backups)` over one
    trained seed's batch of envs; `unit_memory(start)`, every env's `no_backup`."""
    if not isinstance(env, VmapWrapper):
        raise ValueError(f"env of type {type(env).__name__} is invalid for the shield: allowed is a batched env, "
                         "envs.wrap(env, autoreset=False).")
    step = env.env.step

    def unit_act(params, states, key, backups):
        policy_fn = lambda obs: learner.policy(params, obs[None])[0]
        keys = jax.random.split(key, jax.tree.leaves(states)[0].shape[0])
        actions, _, backups = jax.vmap(lambda s, k, b: shield_one(step, policy_fn, s, k, b, config))(
            states, keys, backups)
        return actions, backups

    def unit_memory(start):
        return jax.vmap(lambda s: no_backup(s, config, env.action_size))(start)

    return unit_act, unit_memory
