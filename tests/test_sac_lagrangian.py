"""SAC-Lagrangian (`SACConfig.failure_budget`): the cost critics' target and the multiplier's dual ascent on
hand-computed numbers, the actor's penalty against the cost critics evaluated apart, and the multiplier stepped by
an update."""

import dataclasses
import shutil

import jax
import jax.numpy as jnp
import numpy as np
import pytest

from agents import driver, presets
from agents.checkpoint import Checkpointer
from agents.loop import Parallel, Transition
from agents.sac import SAC, SACConfig, cost_critic_target, dual_ascent

_SMALL = dict(num_envs=4, batch_size=8, min_replay_size=0, max_replay_size=64, policy_hidden_sizes=(8,),
              q_hidden_sizes=(8,))
_FAST = dict(n_step=3, distributional=True, num_atoms=11, v_min=-5.0, v_max=25.0, layer_norm=True, reward_scaling=1.0)
"""Fast SAC's switches (agents/presets.py: SAC_FAST), small, in float32 (bfloat16 compiles slowly on a CPU)."""


def _sac(**overrides) -> SAC:
    return SAC(SACConfig(**{**_SMALL, **overrides}), 3, 2)


def test_the_cost_target_adds_the_larger_discounted_target_cost_critic():
    """c + discount x max(Q'_c): 1 + 0 x 0.5 = 1 (failed), 0 + 0.9 x 0.25 = 0.225, 0.81 + 0 x 0.7 = 0.81."""
    target = cost_critic_target(jnp.array([1.0, 0.0, 0.81]), jnp.array([[0.2, 0.5], [0.25, 0.1], [0.7, 0.3]]),
                                jnp.array([0.0, 0.9, 0.0]))
    np.testing.assert_allclose(np.asarray(target), [1.0, 0.225, 0.81], rtol=1e-6)


def test_dual_ascent_grows_the_multiplier_by_the_failures_over_the_budget():
    """2 of 10 ended episodes failed, budget 5 %: 0.5 + 0.01 x (2 - 0.05 x 10) = 0.515."""
    assert float(dual_ascent(jnp.float32(0.5), 2.0, 10.0, 0.05, 0.01)) == pytest.approx(0.515)


def test_dual_ascent_floors_the_multiplier_at_zero():
    """No failure among 10 ended episodes: 0.001 + 0.01 x (0 - 0.5) < 0 -> 0."""
    assert float(dual_ascent(jnp.float32(0.001), 0.0, 10.0, 0.05, 0.01)) == 0.0


def test_a_state_without_a_budget_holds_no_cost_critics():
    assert _sac().init(jax.random.PRNGKey(0)).cost_q_params is None


def _same(a, b) -> bool:
    """Equal pytrees: the same number of leaves, each equal bit for bit."""
    a, b = jax.tree.leaves(a), jax.tree.leaves(b)
    return len(a) == len(b) and all(np.array_equal(np.asarray(x), np.asarray(y)) for x, y in zip(a, b))


@pytest.mark.parametrize("field", ["policy_params", "q_params", "target_q_params"])
def test_the_budget_leaves_the_other_networks_initialisation_alone(field):
    """The cost critics draw from their own key: the other networks start where they start without a budget."""
    plain, budget = _sac().init(jax.random.PRNGKey(0)), _sac(failure_budget=0.05).init(jax.random.PRNGKey(0))
    assert _same(getattr(plain, field), getattr(budget, field))


@pytest.fixture(scope="module")
def updated_with_and_without_a_budget():
    """One update from the same start without and with a budget, on a step in which no episode failed."""
    step = _step([0, 0, 0, 0], [0, 1, 0, 0])
    return [sac.update(sac.init(jax.random.PRNGKey(0)), step, jax.random.PRNGKey(1), Parallel(4))[0]
            for sac in (_sac(), _sac(failure_budget=0.05))]


@pytest.mark.parametrize("field", ["policy_params", "q_params"])
def test_an_update_under_a_zero_multiplier_learns_as_without_a_budget(updated_with_and_without_a_budget, field):
    """With no failure in the step the multiplier stays 0: the policy and the critics move exactly as they do
    without a budget (the cost critics draw no random numbers of their own)."""
    plain, budget = updated_with_and_without_a_budget
    assert _same(getattr(plain, field), getattr(budget, field))


@pytest.mark.parametrize("switches", [{"reward_scaling": 2.0}, _FAST],
                         ids=["plain", "fast"])
def test_the_actor_loss_adds_the_scaled_multiplier_times_the_larger_cost_critic(switches):
    """loss(cost) - loss(no cost) = reward_scaling x multiplier x mean_s max_i Q_c,i(s, a(s)), with a(s) the same
    reparameterised actions, the cost critics evaluated here apart (min(Q - p) = min Q - p per sample)."""
    sac = _sac(failure_budget=0.05, **switches)
    scaling = sac.config.reward_scaling
    state = sac.init(jax.random.PRNGKey(0))
    rng = np.random.default_rng(1)
    obs = jnp.asarray(rng.normal(size=(8, 3)), jnp.float32)
    noise = jnp.asarray(rng.normal(size=(8, 2)), jnp.float32)
    plain, _ = sac.actor_loss(state.policy_params, state.q_params, obs, noise, 0.1)
    penalised, _ = sac.actor_loss(state.policy_params, state.q_params, obs, noise, 0.1,
                                  (state.cost_q_params, jnp.float32(3.0)))
    action, _, _ = sac._dist(state.policy_params, obs).sample_with_noise(noise)
    cost_q = np.asarray(sac.cost_net.apply(state.cost_q_params, obs, action))  # (8, 2)
    assert float(penalised - plain) == pytest.approx(scaling * 3.0 * cost_q.max(axis=1).mean(), rel=1e-4)


def test_the_cost_critics_learn_the_failure_of_terminal_transitions():
    """A batch of failing steps (cost 1, no bootstrap): 300 gradient steps bring both cost critics to 1."""
    sac = _sac(failure_budget=0.05, learning_rate=1e-2)
    state = sac.init(jax.random.PRNGKey(0))
    rng = np.random.default_rng(2)
    obs = jnp.asarray(rng.normal(size=(8, 3)), jnp.float32)
    mb = {"action": jnp.asarray(rng.uniform(-1, 1, size=(8, 2)), jnp.float32), "cost": jnp.ones(8),
          "discount": jnp.zeros(8)}
    step = jax.jit(lambda s: sac._cost_critic_step(s, mb, obs, obs, jnp.zeros((8, 2)), Parallel(4))[0])
    for _ in range(300):
        state = step(state)
    cost_q = np.asarray(sac.cost_net.apply(state.cost_q_params, obs, mb["action"]))
    np.testing.assert_allclose(cost_q, 1.0, atol=0.05)


def test_a_cost_critic_step_reports_the_error_against_the_bootstrapped_target():
    """The loss of one step: 0.5 x mean over samples and both cost critics of (Q_c - (c + d x max_i Q'_c,i(s',
    a')))^2, the target cost critics (here other parameters than the online ones) evaluated apart at the next
    actions drawn with the given noise."""
    sac = _sac(failure_budget=0.05)
    state = sac.init(jax.random.PRNGKey(0))
    state = state.replace(target_cost_q_params=sac.cost_net.init(jax.random.PRNGKey(9), jnp.zeros((1, 3)),
                                                                 jnp.zeros((1, 2))))
    rng = np.random.default_rng(4)
    obs, next_obs = (jnp.asarray(rng.normal(size=(8, 3)), jnp.float32) for _ in range(2))
    noise = jnp.asarray(rng.normal(size=(8, 2)), jnp.float32)
    mb = {"action": jnp.asarray(rng.uniform(-1, 1, size=(8, 2)), jnp.float32),
          "cost": jnp.asarray([0, 1, 0, 0.9, 0, 0, 1, 0], jnp.float32),
          "discount": jnp.asarray([0.97, 0, 0.97, 0, 0.9, 0.97, 0, 0.97], jnp.float32)}
    _, metrics = sac._cost_critic_step(state, mb, obs, next_obs, noise, Parallel(4))
    next_action, _, _ = sac._dist(state.policy_params, next_obs).sample_with_noise(noise)
    next_q = np.asarray(sac.cost_net.apply(state.target_cost_q_params, next_obs, next_action)).max(axis=1)
    target = np.asarray(mb["cost"]) + np.asarray(mb["discount"]) * next_q
    q = np.asarray(sac.cost_net.apply(state.cost_q_params, obs, mb["action"]))
    assert float(metrics["loss/cost_critic"]) == pytest.approx(0.5 * np.mean((q - target[:, None]) ** 2), rel=1e-5)


def _step(termination, truncation) -> Transition:
    """One vector step of the 4 envs with random observations and actions, and the given episode ends."""
    rng = np.random.default_rng(3)
    f = lambda *shape: jnp.asarray(rng.normal(size=(1, 4) + shape), jnp.float32)  # noqa: E731
    return Transition(obs=f(3), action=jnp.tanh(f(2)), reward=f(), termination=jnp.asarray([termination], jnp.float32),
                      truncation=jnp.asarray([truncation], jnp.float32), next_obs=f(3), extras={})


def test_an_update_steps_the_multiplier_on_its_ended_episodes():
    """2 failures and 1 time-out among 4 envs: 0 + 0.1 x (2 - 0.25 x 3) = 0.125."""
    sac = _sac(failure_budget=0.25, multiplier_lr=0.1)
    state, _ = sac.update(sac.init(jax.random.PRNGKey(0)), _step([1, 0, 1, 0], [0, 1, 0, 0]),
                          jax.random.PRNGKey(1), Parallel(4))
    assert float(state.multiplier) == pytest.approx(0.125)


@pytest.mark.parametrize("name, count", [("lagrange/failed_episodes", 2.0), ("lagrange/ended_episodes", 3.0)])
def test_an_update_reports_its_failed_and_ended_episodes(name, count):
    sac = _sac(failure_budget=0.25)
    _, metrics = sac.update(sac.init(jax.random.PRNGKey(0)), _step([1, 0, 1, 0], [0, 1, 0, 0]),
                            jax.random.PRNGKey(1), Parallel(4))
    assert float(metrics[name]) == count


def test_fast_sac_steps_the_multiplier_once_its_first_window_is_written():
    """n-step 3: the first two updates fill the buffer (multiplier held), the third steps it by 0.1 x (2 - 0.25 x 3)."""
    sac = _sac(failure_budget=0.25, multiplier_lr=0.1, **_FAST)
    state = sac.init(jax.random.PRNGKey(0))
    update = jax.jit(lambda s, key: sac.update(s, _step([1, 0, 1, 0], [0, 1, 0, 0]), key, Parallel(4))[0])
    held = []
    for k in range(3):
        held.append(float(state.multiplier))
        state = update(state, jax.random.PRNGKey(k))
    assert held + [float(state.multiplier)] == pytest.approx([0.0, 0.0, 0.0, 0.125])


def test_an_update_while_the_buffer_fills_leaves_the_multiplier_alone():
    sac = _sac(failure_budget=0.25, multiplier_lr=0.1, min_replay_size=64)
    state, _ = sac.update(sac.init(jax.random.PRNGKey(0)), _step([1, 0, 1, 0], [0, 1, 0, 0]),
                          jax.random.PRNGKey(1), Parallel(4))
    assert float(state.multiplier) == 0.0


def test_an_update_moves_the_cost_critics():
    sac = _sac(failure_budget=0.25)
    before = sac.init(jax.random.PRNGKey(0))
    after, _ = sac.update(before, _step([1, 0, 1, 0], [0, 1, 0, 0]), jax.random.PRNGKey(1), Parallel(4))
    changed = [not np.array_equal(np.asarray(a), np.asarray(b))
               for a, b in zip(jax.tree.leaves(before.cost_q_params), jax.tree.leaves(after.cost_q_params))]
    assert all(changed)


@pytest.mark.parametrize("field, value", [("failure_budget", 1.5), ("failure_budget", -0.1),
                                          ("failure_budget", float("nan")), ("multiplier_lr", 0.0)])
def test_impossible_lagrangian_settings_are_refused_naming_the_field(field, value):
    with pytest.raises(ValueError, match=f"algo.{field}"):
        SACConfig(**{"failure_budget": 0.05, field: value}).validate()


def test_a_checkpoint_keeps_the_multiplier_and_the_cost_critics(tmp_path):
    """What --resume continues from: the learner state read back from an orbax checkpoint."""
    sac = _sac(failure_budget=0.05)
    state = sac.init(jax.random.PRNGKey(0)).replace(multiplier=jnp.float32(7.25))
    checkpointer = Checkpointer(str(tmp_path))
    checkpointer.save(1, state, {})
    restored, _ = checkpointer.restore(1, sac.init(jax.random.PRNGKey(1)))
    assert float(restored.multiplier) == 7.25
    for a, b in zip(jax.tree.leaves(state.cost_q_params), jax.tree.leaves(restored.cost_q_params)):
        np.testing.assert_array_equal(np.asarray(a), np.asarray(b))


def test_a_learner_only_resume_keeps_the_multiplier_and_holds_it_while_the_buffer_refills(tmp_path):
    """A resumed run without env states (`checkpoint_envs=False`) starts from the stored multiplier and cost critics,
    refills the buffer (the point-mass probe's min_replay_size, 1,024 transitions) without stepping them, then steps
    again."""
    config = presets.make_config("point-mass-sac", logdir=str(tmp_path / "a"), stop_after_steps=1_600,
                                 num_timesteps=3_200, eval_envs=0, log_every=1_600, checkpoint_envs=False,
                                 tensorboard=False, progress=False)
    config = dataclasses.replace(config, algo=dataclasses.replace(config.algo, failure_budget=0.01, multiplier_lr=0.5))
    first = driver.train(config).state.learner
    assert float(first.multiplier[0]) > 0.0  # the probe's early episodes leave the arena: the multiplier grew
    shutil.copytree(tmp_path / "a", tmp_path / "b")
    # 63 vector steps of 16 envs: the buffer one step short of 1,024 transitions, no update has trained yet.
    refilled = driver.train(dataclasses.replace(config, resume=True, stop_after_steps=1_600 + 1_008)).state.learner
    assert int(refilled.replay.rows[0]) == 63
    assert _same(refilled.multiplier, first.multiplier)
    assert _same((refilled.cost_q_params, refilled.target_cost_q_params, refilled.cost_q_opt),
                 (first.cost_q_params, first.target_cost_q_params, first.cost_q_opt))
    resumed = driver.train(dataclasses.replace(config, logdir=str(tmp_path / "b"), resume=True, stop_after_steps=0))
    assert float(resumed.state.learner.multiplier[0]) != float(first.multiplier[0])  # stepped after the refill
