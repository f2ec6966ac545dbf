"""PPO-Lagrangian (`PPOConfig.failure_budget`): the multiplier's dual ascent on hand-computed numbers, and its
reward shaping against an update on rewards shaped by hand."""

import dataclasses

import jax
import jax.numpy as jnp
import numpy as np
import pytest

from agents.checkpoint import Checkpointer
from agents.config import TrainConfig, validate
from agents.loop import Parallel, Transition
from agents.ppo import PPO, PPOConfig
from agents.sac import SACConfig
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
    """4 episodes ended (three by time), 1 of them failed: share 0.25; 0.5 + 10 x (0.25 - 0.05) = 2.5."""
    ppo = _ppo(failure_budget=0.05, multiplier_lr=10.0)
    termination = _flags([[0, 1, 0, 0], [0, 0, 0, 0], [0, 0, 0, 0]])
    truncation = _flags([[0, 0, 0, 0], [0, 0, 0, 0], [1, 0, 1, 1]])
    multiplier, share = ppo.dual_ascent(jnp.float32(0.5), _batch(ppo, termination, truncation), Parallel(4), 0)
    assert float(share) == pytest.approx(0.25)
    assert float(multiplier) == pytest.approx(2.5)


def test_dual_ascent_floors_the_multiplier_at_zero():
    """No failure among 2 ended episodes: 0.1 + 10 x (0 - 0.05) = -0.4, floored at 0."""
    ppo = _ppo(failure_budget=0.05, multiplier_lr=10.0)
    truncation = _flags([[0, 0, 0, 0], [0, 0, 0, 0], [1, 1, 0, 0]])
    multiplier, _ = ppo.dual_ascent(jnp.float32(0.1), _batch(ppo, jnp.zeros((3, 4)), truncation), Parallel(4), 0)
    assert float(multiplier) == 0.0


def test_dual_ascent_keeps_the_multiplier_when_no_episode_ended():
    ppo = _ppo(failure_budget=0.05, multiplier_lr=10.0)
    multiplier, _ = ppo.dual_ascent(jnp.float32(0.7), _batch(ppo, jnp.zeros((3, 4)), jnp.zeros((3, 4))), Parallel(4), 0)
    assert float(multiplier) == pytest.approx(0.7)


def _delayed(updates):
    """The first test's batch after update number `updates`, with the ascent starting at 25 env steps: 12 steps an
    update (batch_size 2 x num_minibatches 2 x unroll_length 3), so from update 3 (25 / 12 rounded up) on."""
    ppo = _ppo(failure_budget=0.05, multiplier_lr=10.0, multiplier_start=25)
    termination = _flags([[0, 1, 0, 0], [0, 0, 0, 0], [0, 0, 0, 0]])
    truncation = _flags([[0, 0, 0, 0], [0, 0, 0, 0], [1, 0, 1, 1]])
    return ppo.dual_ascent(jnp.float32(0.5), _batch(ppo, termination, truncation), Parallel(4), jnp.int32(updates))


def test_dual_ascent_holds_the_multiplier_before_multiplier_start():
    assert float(_delayed(2)[0]) == pytest.approx(0.5)


def test_dual_ascent_reports_the_share_before_multiplier_start():
    assert float(_delayed(2)[1]) == pytest.approx(0.25)


def test_dual_ascent_steps_from_the_update_that_reaches_multiplier_start():
    assert float(_delayed(3)[0]) == pytest.approx(2.5)


_TERMINATION = _flags([[0, 1, 0, 0], [0, 0, 0, 1], [0, 0, 0, 0]])
_TRUNCATION = _flags([[0, 0, 0, 0], [0, 0, 0, 0], [1, 0, 1, 0]])


def _max_difference(a, b) -> float:
    return max(float(jnp.max(jnp.abs(x - y))) for x, y in zip(jax.tree.leaves(a), jax.tree.leaves(b)))


def test_update_subtracts_the_multiplier_from_failure_steps_before_scaling():
    """An update with multiplier 3 and reward scaling 0.5 equals, parameter for parameter, a budget-free update on a
    batch whose rewards are (r - 3 x failure) x 0.5, with scaling 1 (the same initial parameters and keys)."""
    lagrangian, plain = _ppo(failure_budget=0.05, reward_scaling=0.5), _ppo()
    batch = _batch(plain, _TERMINATION, _TRUNCATION)
    state = lagrangian.init(jax.random.PRNGKey(3)).replace(multiplier=jnp.float32(3.0))
    key = jax.random.PRNGKey(4)
    got, _ = lagrangian.update(state, batch, key, Parallel(4))
    shaped = batch._replace(reward=(batch.reward - 3.0 * _TERMINATION) * 0.5)
    want, _ = plain.update(plain.init(jax.random.PRNGKey(3)), shaped, key, Parallel(4))
    assert _max_difference(got.params, want.params) < 1e-6


def test_the_reference_update_differs_without_the_shaping():
    """The comparison above is not vacuous: the same update on the unshaped, unscaled rewards moves elsewhere."""
    plain = _ppo()
    batch = _batch(plain, _TERMINATION, _TRUNCATION)
    key = jax.random.PRNGKey(4)
    unshaped, _ = plain.update(plain.init(jax.random.PRNGKey(3)), batch, key, Parallel(4))
    shaped, _ = plain.update(plain.init(jax.random.PRNGKey(3)),
                             batch._replace(reward=(batch.reward - 3.0 * _TERMINATION) * 0.5), key, Parallel(4))
    assert _max_difference(unshaped.params, shaped.params) > 1e-4


def test_update_steps_the_multiplier_after_the_batch():
    """2 failures among the 4 ended episodes: 3 + 10 x (0.5 - 0.05) = 7.5 in the new state."""
    lagrangian = _ppo(failure_budget=0.05, multiplier_lr=10.0)
    state = lagrangian.init(jax.random.PRNGKey(3)).replace(multiplier=jnp.float32(3.0))
    new, _ = lagrangian.update(state, _batch(lagrangian, _TERMINATION, _TRUNCATION), jax.random.PRNGKey(4),
                               Parallel(4))
    assert float(new.multiplier) == pytest.approx(7.5)


def _delayed_update(updates):
    """The batch above after update number `updates`, the ascent starting at 12 env steps (update 1)."""
    lagrangian = _ppo(failure_budget=0.05, multiplier_lr=10.0, multiplier_start=12)
    state = lagrangian.init(jax.random.PRNGKey(3)).replace(multiplier=jnp.float32(3.0), updates=jnp.int32(updates))
    new, _ = lagrangian.update(state, _batch(lagrangian, _TERMINATION, _TRUNCATION), jax.random.PRNGKey(4),
                               Parallel(4))
    return float(new.multiplier)


def test_update_holds_the_multiplier_before_multiplier_start():
    assert _delayed_update(0) == pytest.approx(3.0)


def test_update_steps_the_multiplier_from_multiplier_start():
    assert _delayed_update(1) == pytest.approx(7.5)


def test_dual_ascent_counts_the_episodes_of_every_device():
    """Two devices (a vmapped axis with the mesh's name): one failure of 2 ended episodes on the first, none of 2 on
    the second. Both take the global share 0.25 (0.5 + 10 x 0.2 = 2.5), not their own 0.5 and 0."""
    ppo = _ppo(failure_budget=0.05, multiplier_lr=10.0)
    termination = _flags([[[0, 1], [0, 0], [0, 0]], [[0, 0], [0, 0], [0, 0]]])
    truncation = _flags([[[0, 0], [0, 0], [1, 0]], [[0, 0], [0, 0], [1, 1]]])
    batches = [_batch(ppo, termination[d], truncation[d]) for d in range(2)]
    stacked = jax.tree.map(lambda *x: jnp.stack(x), *batches)
    par = Parallel(4, num_devices=2, axis_name="dev")
    multiplier, _ = jax.vmap(lambda b: ppo.dual_ascent(jnp.float32(0.5), b, par, 0), axis_name="dev")(stacked)
    assert np.allclose(np.asarray(multiplier), 2.5)


def test_a_state_without_a_budget_holds_no_multiplier():
    assert _ppo().init(jax.random.PRNGKey(0)).multiplier is None


@pytest.mark.parametrize("field, value", [("failure_budget", 1.5), ("failure_budget", -0.1), ("multiplier_lr", 0.0),
                                          ("multiplier_start", -1), ("multiplier_start", 2.5)])
def test_impossible_lagrangian_settings_are_refused_naming_the_field(field, value):
    with pytest.raises(ValueError, match=f"algo.{field}"):
        PPOConfig(**{"failure_budget": 0.05, field: value}).validate()


def test_a_multiplier_start_without_a_budget_is_refused():
    with pytest.raises(ValueError, match="algo.multiplier_start=100 is invalid without algo.failure_budget"):
        PPOConfig(multiplier_start=100).validate()


def _point_mass(multiplier_start, num_timesteps=36):
    """3 updates of 12 env steps: the ascent may begin at update 1 at the latest (12 env steps), so that update 2
    sees the multiplier."""
    algo = PPOConfig(**_SMALL, failure_budget=0.05, multiplier_start=multiplier_start)
    return TrainConfig(env_name="point-mass", env=envs.default_config("point-mass"), num_timesteps=num_timesteps,
                       algo=algo)


def test_a_multiplier_start_that_acts_on_no_update_is_refused():
    with pytest.raises(ValueError, match="algo.multiplier_start=13 is invalid with num_timesteps=36: .* at most 12"):
        validate(_point_mass(13))


def test_the_latest_multiplier_start_that_acts_is_accepted():
    validate(_point_mass(12))  # raises if refused


@pytest.mark.parametrize("algo", [PPOConfig(**_SMALL), SACConfig()])
def test_a_run_without_steps_is_refused_naming_num_timesteps(algo):
    config = TrainConfig(env_name="point-mass", env=envs.default_config("point-mass"), num_timesteps=0, algo=algo)
    with pytest.raises(ValueError, match="^num_timesteps=0 is invalid"):
        validate(config)


@pytest.mark.parametrize("algo", [PPOConfig(failure_budget=0.05), SACConfig(failure_budget=0.05)])
def test_a_budget_is_refused_where_reaching_terminates(algo):
    env = dataclasses.replace(envs.default_config("ur5e-reach-avoid"), success="reach_and_terminate")
    config = TrainConfig(env_name="ur5e-reach-avoid", env=env, algo=algo)
    with pytest.raises(ValueError, match="algo.failure_budget=0.05 is invalid with env.success"):
        validate(config)


def test_a_checkpoint_keeps_the_multiplier(tmp_path):
    """What --resume continues from: the multiplier read back from an orbax checkpoint of the learner state."""
    ppo = _ppo(failure_budget=0.05)
    state = ppo.init(jax.random.PRNGKey(0)).replace(multiplier=jnp.float32(7.25))
    checkpointer = Checkpointer(str(tmp_path))
    checkpointer.save(1, state, {})
    restored, _ = checkpointer.restore(1, ppo.init(jax.random.PRNGKey(1)))
    assert float(restored.multiplier) == 7.25
