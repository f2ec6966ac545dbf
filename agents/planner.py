"""A sampling-based model-predictive planner (MPPI) that uses the environment itself as its model.

A reference for the learners, not a competitor: at every control step it copies each env's state, rolls
`samples` perturbed action sequences of `horizon` steps through the very same `env.step` (so it knows the
exact dynamics, the target and the obstacles' future motion, which no observation gives a learner), weights
them by their returns and executes the first action of the weighted mean (model-predictive path integral
control, Williams et al. 2017, with a return-relative temperature). Its price is compute: `samples x horizon
x iterations` simulated env steps per executed one (`PlannerConfig.model_steps_per_step`).

The plan is warm-started: after each step the mean sequence shifts by one step and repeats its last action
(for absolute control that holds the last commanded pose; for relative control it keeps the last step).
The first plan of an episode commands the episode's initial pose (`agents.baselines`' standstill), so an
unplanned arm stands still instead of falling.

`make_act(env, config)` returns the `(act, memory)` pair of `agents.loop.make_evaluate`: eval.py evaluates the
planner like any other policy (`--policy mppi`, `agents.evaluation.planner_policy`).
"""

from __future__ import annotations

import dataclasses

import jax
import jax.numpy as jnp

from agents.baselines import joint_target_action
from envs import validation
from envs.wrappers import VmapWrapper

NAME = "mppi"
"""The planner's policy name (eval.py --policy mppi)."""


@dataclasses.dataclass(frozen=True)
class PlannerConfig:
    """Options of the MPPI planner (`--planner.<field>` in eval.py)."""

    samples: int = 64
    """Action sequences sampled per planning iteration (K); the current mean plan is always one of them."""
    horizon: int = 16
    """Env steps each sampled sequence is simulated ahead (H)."""
    iterations: int = 1
    """Refinements of the plan per control step, each from the previous one's weighted mean."""
    temperature: float = 0.05
    """Softmax temperature as a fraction of the spread (max - min) of the sampled returns: small values follow
    the best sequence, large ones average all of them."""
    noise: float = 0.3
    """Standard deviation of the Gaussian perturbation of each action (actions live in [-1, 1])."""
    discount: float = 1.0
    """Discount of the simulated rewards along the horizon."""

    def __post_init__(self):
        validation.integer("samples", self.samples, 2)
        validation.integer("horizon", self.horizon, 1)
        validation.integer("iterations", self.iterations, 1)
        validation.positive("temperature", self.temperature)
        validation.positive("noise", self.noise)
        validation.in_range("discount", self.discount, 0.0, 1.0)

    @property
    def model_steps_per_step(self) -> int:
        """Env steps simulated in the model per executed env step (the planner's compute cost)."""
        return self.samples * self.horizon * self.iterations


def initial_action(env, start_state):
    """The first plan's action for one env: command the initial pose (arms) or stand still (probe tasks)."""
    base = env.unwrapped
    robot = getattr(base, "robot", None)
    if robot is None:
        return jnp.zeros((env.action_size,))
    data = start_state.pipeline_state
    delta_base = data.ctrl if base.config.relative_to == "target" else data.qpos
    return joint_target_action(base.config, robot, data.qpos, delta_base)


FAILURE_METRICS = ("self_collision", "obstacle_collision", "physics_nan")
"""The per-step env metrics that make a simulated step a failure (the arms' collisions and a NaN step, `envs.arm`)."""


def failed(state) -> jax.Array:
    """Whether a simulated step failed: any of `FAILURE_METRICS` the env reports (False for envs without them)."""
    flags = [state.metrics[name] > 0 for name in FAILURE_METRICS if name in state.metrics]
    return jnp.any(jnp.stack(flags), axis=0) if flags else jnp.zeros(jnp.shape(state.reward), bool)


def sequence_outcomes(step, state, actions, discount: float):
    """`(returns (K,), fails (K,))` of the `(K, H, A)` action sequences simulated from one env `state` by the
    single-env `step`: discounted returns, where rewards after a simulated episode's end (termination or time
    limit) do not count, and whether a sequence collides before its episode ends (`failed`)."""
    states = jax.tree.map(lambda x: jnp.broadcast_to(x, (actions.shape[0],) + jnp.shape(x)), state)

    def advance(loop, action_t):
        states, alive, total, weight, fails = loop
        states = jax.vmap(step)(states, action_t)
        total = total + alive * weight * states.reward
        fails = fails | ((alive > 0) & failed(states))
        alive = alive * (1.0 - states.done)
        return (states, alive, total, weight * discount, fails), None

    ones = jnp.ones(actions.shape[:1])
    start = (states, ones, jnp.zeros_like(ones), jnp.ones(()), jnp.zeros(actions.shape[:1], bool))
    (_, _, total, _, fails), _ = jax.lax.scan(advance, start, jnp.swapaxes(actions, 0, 1))
    return total, fails


def sequence_returns(step, state, actions, discount: float):
    """The discounted returns `(K,)` of `sequence_outcomes`."""
    return sequence_outcomes(step, state, actions, discount)[0]


def mppi_weights(returns, temperature: float):
    """Softmax weights of the sampled returns at `temperature` times their spread (all equal if they are)."""
    spread = jnp.max(returns) - jnp.min(returns)
    scaled = (returns - jnp.max(returns)) / jnp.maximum(temperature * spread, 1e-12)
    return jax.nn.softmax(scaled)


def refine(step, state, plan, key, config: PlannerConfig):
    """One MPPI iteration for one env: sample around `plan` `(H, A)`, simulate, return the weighted mean plan."""
    noise = config.noise * jax.random.normal(key, (config.samples,) + plan.shape)
    noise = noise.at[0].set(0.0)  # the current plan competes unperturbed
    candidates = jnp.clip(plan[None] + noise, -1.0, 1.0)
    weights = mppi_weights(sequence_returns(step, state, candidates, config.discount), config.temperature)
    return jnp.einsum("k,kha->ha", weights, candidates)


def plan_one(step, state, plan, key, config: PlannerConfig):
    """`(action, next plan)` for one env: `iterations` refinements, then the first action and the shifted plan."""
    plan, _ = jax.lax.scan(lambda p, k: (refine(step, state, p, k, config), None), plan,
                           jax.random.split(key, config.iterations))
    return plan[0], jnp.concatenate([plan[1:], plan[-1:]])


def make_act(env, config: PlannerConfig):
    """`(act, memory)` for `agents.loop.make_evaluate` over the batched, non-resetting evaluation env `env`
    (`envs.wrap(..., autoreset=False)`): `memory(start)` is each env's first plan `(n, H, A)`;
    `act(params, state, start, key, plans)` plans every env (params are unused) and returns `(actions, plans)`."""
    if not isinstance(env, VmapWrapper):
        raise ValueError(f"env of type {type(env).__name__} is invalid for the planner: allowed is a batched env, "
                         "envs.wrap(env, autoreset=False).")
    single = env.env  # the batch's per-env stack: episode limit included, no auto-reset
    step = single.step

    def memory(start):
        first = jax.vmap(lambda s: initial_action(env, s))(start)
        return jnp.repeat(first[:, None], config.horizon, axis=1)

    def act(params, state, start, key, plans):
        keys = jax.random.split(key, plans.shape[0])
        return jax.vmap(lambda s, p, k: plan_one(step, s, p, k, config))(state, plans, keys)

    return act, memory
