"""PPO-Lagrangian (`PPOConfig.failure_budget`): the multiplier's dual ascent on hand-computed numbers, and its
reward shaping against an update on rewards shaped by hand."""

import dataclasses

import jax
import jax.numpy as jnp
import numpy as np
import pytest

from agents.config import TrainConfig, validate
from agents.loop import Parallel, Transition
from agents.ppo import PPO, PPOConfig
import envs

_SMALL = dict(num_envs=4, batch_size=2, num_minibatches=2, unroll_length=3, updates_per_batch=2,
              policy_hidden_sizes=(8,), value_hidden_sizes=(8,))


def _flags(rows):
    """(steps, envs) float32 array from nested lists."""
    return jnp.asarray(rows, jnp.float32)


def _batch(ppo: PPO, termination, truncation, key=0) -> Transition:
    """A batch of `(steps_per_update, num_envs)` transitions with random observations and rewards, its actions
    from the policy."""
    steps, envs = termination.shape
    rng = np.random.default_rng(key)
    obs = jnp.asarray(rng.normal(size=(steps, envs, ppo.observation_size)), jnp.float32)
    state = ppo.init(jax.random.PRNGKey(key))
    action, extras = jax.vmap(lambda o, k: ppo.act(state, o, k, Parallel(envs)))(
        obs, jax.random.split(jax.random.PRNGKey(key + 1), steps))
    return Transition(obs=obs, action=action, reward=jnp.asarray(rng.normal(size=(steps, envs)), jnp.float32),
                      termination=termination, truncation=truncation,
                      next_obs=jnp.asarray(rng.normal(size=obs.shape), jnp.float32), extras=extras)


def _ppo(**overrides) -> PPO:
    return PPO(PPOConfig(**_SMALL, **overrides), 3, 2, 10)


def test_dual_ascent_grows_the_multiplier_by_the_excess_failure_share():
    """4 episodes ended (one by time), 1 of them failed: share 0.25; 0.5 + 10 x (0.25 - 0.05) = 2.5."""
    ppo = _ppo(failure_budget=0.05, multiplier_lr=10.0)
    termination = _flags([[0, 1, 0, 0], [0, 0, 0, 0], [0, 0, 0, 0]])
    truncation = _flags([[0, 0, 0, 0], [0, 0, 0, 0], [1, 0, 1, 1]])
    multiplier, share = ppo.dual_ascent(jnp.float32(0.5), _batch(ppo, termination, truncation), Parallel(4))
    assert float(share) == pytest.approx(0.25)
    assert float(multiplier) == pytest.approx(2.5)


def test_dual_ascent_floors_the_multiplier_at_zero():
    """No failure among 2 ended episodes: 0.1 + 10 x (0 - 0.05) = -0.4, floored at 0."""
    ppo = _ppo(failure_budget=0.05, multiplier_lr=10.0)
    truncation = _flags([[0, 0, 0, 0], [0, 0, 0, 0], [1, 1, 0, 0]])
    multiplier, _ = ppo.dual_ascent(jnp.float32(0.1), _batch(ppo, jnp.zeros((3, 4)), truncation), Parallel(4))
    assert float(multiplier) == 0.0


def test_dual_ascent_keeps_the_multiplier_when_no_episode_ended():
    ppo = _ppo(failure_budget=0.05, multiplier_lr=10.0)
    multiplier, _ = ppo.dual_ascent(jnp.float32(0.7), _batch(ppo, jnp.zeros((3, 4)), jnp.zeros((3, 4))), Parallel(4))
    assert float(multiplier) == pytest.approx(0.7)


def test_update_subtracts_the_multiplier_from_failure_steps_only():
    """An update with multiplier 3 equals, parameter for parameter, a budget-free update on a batch whose failure
    steps earn 3 less (the same initial parameters and keys)."""
    termination = _flags([[0, 1, 0, 0], [0, 0, 0, 1], [0, 0, 0, 0]])
    truncation = _flags([[0, 0, 0, 0], [0, 0, 0, 0], [1, 0, 1, 0]])
    lagrangian, plain = _ppo(failure_budget=0.05), _ppo()
    batch = _batch(plain, termination, truncation)
    state = lagrangian.init(jax.random.PRNGKey(3)).replace(multiplier=jnp.float32(3.0))
    key = jax.random.PRNGKey(4)
    got, metrics = lagrangian.update(state, batch, key, Parallel(4))
    shaped = batch._replace(reward=batch.reward - 3.0 * termination)
    want, _ = plain.update(plain.init(jax.random.PRNGKey(3)), shaped, key, Parallel(4))
    unshaped, _ = plain.update(plain.init(jax.random.PRNGKey(3)), batch, key, Parallel(4))
    diff = lambda a, b: max(float(jnp.max(jnp.abs(x - y))) for x, y in zip(jax.tree.leaves(a), jax.tree.leaves(b)))
    assert diff(got.params, want.params) < 1e-6
    assert diff(unshaped.params, want.params) > 1e-4  # the shaping changes the update at all
    assert float(metrics["lagrange/multiplier"]) == pytest.approx(3.0 + 10.0 * (2 / 4 - 0.05))


def test_a_state_without_a_budget_holds_no_multiplier():
    assert _ppo().init(jax.random.PRNGKey(0)).multiplier is None


@pytest.mark.parametrize("field, value", [("failure_budget", 1.5), ("failure_budget", -0.1), ("multiplier_lr", 0.0)])
def test_impossible_lagrangian_settings_are_refused_naming_the_field(field, value):
    with pytest.raises(ValueError, match=f"algo.{field}"):
        PPOConfig(**{field: value}).validate()


def test_a_budget_is_refused_where_reaching_terminates():
    env = dataclasses.replace(envs.default_config("ur5e-reach-avoid"), success="reach_and_terminate")
    config = TrainConfig(env_name="ur5e-reach-avoid", env=env, algo=PPOConfig(failure_budget=0.05))
    with pytest.raises(ValueError, match="algo.failure_budget=0.05 is invalid with env.success"):
        validate(config)
