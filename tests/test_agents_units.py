"""The formulas of the learners on hand-computed numbers (no training)."""

import math

import jax
import jax.numpy as jnp
import numpy as np
import optax
import pytest

from agents import normalizer
from agents.distributions import TanhNormal
from agents.loop import Parallel
from agents.networks import MLP, TwinQ
from agents.ppo import PPO, PPOConfig, gae, learning_rate, normalize_per_minibatch, popart_preserve, ppo_loss_terms
from agents.sac import SAC, SACConfig, actor_loss, critic_loss, critic_target, polyak, temperature_loss


# -- tanh-Gaussian ----------------------------------------------------------------------------


def test_tanh_normal_log_prob_finite_at_and_beyond_bounds():
    dist = TanhNormal(jnp.array([[0.3, -2.0]]), jnp.array([[0.5, 0.01]]))
    for a in ([1.0, -1.0], [-1.0, 1.0], [1.5, -7.0], [0.999999, -0.999999]):
        lp = dist.log_prob(jnp.array([a]))
        assert np.all(np.isfinite(np.asarray(lp))), a
    # Pre-squash values far out in the tails, where tanh(u) == +-1 in float32.
    u = jnp.array([[30.0, -50.0]])
    assert np.all(np.isfinite(np.asarray(dist.log_prob_raw(u))))
    assert np.asarray(jnp.tanh(u)).tolist() == [[1.0, -1.0]]


def test_tanh_normal_log_prob_matches_change_of_variables():
    mean, std = jnp.array([0.2, -0.4]), jnp.array([0.7, 1.3])
    u = jnp.array([0.5, -1.1])
    a = np.tanh(np.asarray(u, np.float64))
    normal = -0.5 * ((np.asarray(u) - np.asarray(mean)) / np.asarray(std)) ** 2 - np.log(np.asarray(std)) - 0.5 * math.log(2 * math.pi)
    expected = np.sum(normal - np.log(1 - a**2))
    dist = TanhNormal(mean, std)
    np.testing.assert_allclose(float(dist.log_prob_raw(u)), expected, rtol=1e-5)
    np.testing.assert_allclose(float(dist.log_prob(jnp.asarray(a, jnp.float32))), expected, rtol=1e-4)
    import distrax
    reference = distrax.Transformed(distrax.MultivariateNormalDiag(mean, std), distrax.Block(distrax.Tanh(), 1))
    np.testing.assert_allclose(float(dist.log_prob(jnp.asarray(a, jnp.float32))), float(reference.log_prob(jnp.asarray(a, jnp.float32))), rtol=1e-4)


def test_tanh_normal_sampling_entropy_and_mode():
    dist = TanhNormal(jnp.zeros((20000, 1)) + 0.3, jnp.full((20000, 1), 0.2))
    a, u, lp = dist.sample_and_log_prob(jax.random.PRNGKey(0))
    np.testing.assert_allclose(np.asarray(a), np.tanh(np.asarray(u)), rtol=1e-6)
    np.testing.assert_allclose(np.asarray(lp), np.asarray(dist.log_prob_raw(u)))
    assert np.all(np.abs(np.asarray(a)) < 1)
    # Entropy estimate: H[N] + E[log(1 - tanh^2)], compared with a Monte-Carlo -E[log pi].
    entropy = float(jnp.mean(dist.entropy(jax.random.PRNGKey(1))))
    np.testing.assert_allclose(entropy, -float(jnp.mean(lp)), atol=0.02)
    assert float(dist.mode()[0, 0]) == pytest.approx(math.tanh(0.3), rel=1e-6)


# -- normaliser ---------------------------------------------------------------------------------


def test_normalizer_running_merge_equals_full_batch():
    x = jax.random.normal(jax.random.PRNGKey(0), (3, 50, 4)) * jnp.array([1.0, 2.0, 0.1, 5.0]) + 3.0
    stats = normalizer.init(4)
    for part in x:  # three batches
        stats = normalizer.update(stats, part)
    flat = np.asarray(x).reshape(-1, 4)
    np.testing.assert_allclose(np.asarray(stats.mean), flat.mean(0), rtol=1e-5)
    np.testing.assert_allclose(np.asarray(stats.var), flat.var(0), rtol=1e-4)
    assert float(stats.count) == 150
    y = normalizer.normalize(stats, jnp.asarray(flat))
    np.testing.assert_allclose(np.asarray(y).std(0), 1.0, rtol=1e-3)
    assert float(jnp.max(normalizer.normalize(stats, jnp.full((1, 4), 1e6), clip=5.0))) == 5.0


def test_normalizer_decay_tracks_recent_batches():
    stats = normalizer.init(())
    for value in [0.0] * 50 + [10.0] * 50:
        stats = normalizer.update(stats, jnp.full((8,), value), decay=0.9)
    assert float(stats.mean) == pytest.approx(10.0 * (1 - 0.9**50), rel=1e-4)


# -- PPO ----------------------------------------------------------------------------------------


def _gae_loop(r, v, nv, term, done, gamma, lam):
    T = len(r)
    adv = np.zeros(T)
    last = 0.0
    for t in reversed(range(T)):
        delta = r[t] + gamma * (1 - term[t]) * nv[t] - v[t]
        last = delta + gamma * lam * (1 - done[t]) * last
        adv[t] = last
    return adv, adv + v


def test_gae_matches_python_loop_with_terminations_and_truncations():
    rng = np.random.default_rng(0)
    T, N = 12, 3
    r, v, nv = rng.normal(size=(T, N)), rng.normal(size=(T, N)), rng.normal(size=(T, N))
    term = np.zeros((T, N))
    trunc = np.zeros((T, N))
    term[3, 0] = term[7, 1] = 1
    trunc[5, 0] = trunc[2, 2] = trunc[11, 1] = 1
    done = np.maximum(term, trunc)
    adv, targets = gae(*(jnp.asarray(a, jnp.float32) for a in (r, v, nv, term, done)), 0.97, 0.95)
    for n in range(N):
        ref_adv, ref_t = _gae_loop(r[:, n], v[:, n], nv[:, n], term[:, n], done[:, n], 0.97, 0.95)
        np.testing.assert_allclose(np.asarray(adv)[:, n], ref_adv, rtol=1e-5, atol=1e-5)
        np.testing.assert_allclose(np.asarray(targets)[:, n], ref_t, rtol=1e-5, atol=1e-5)


def test_truncation_bootstraps_and_termination_does_not():
    # One step each: reward 1, V(s) = 0, V(final obs) = 10.
    ones = jnp.ones((1, 2))
    rewards, values, next_values = ones, 0 * ones, 10 * ones
    termination = jnp.array([[1.0, 0.0]])  # env 0 terminated, env 1 truncated
    done = ones
    adv, _ = gae(rewards, values, next_values, termination, done, 0.9, 0.95)
    np.testing.assert_allclose(np.asarray(adv), [[1.0, 1.0 + 0.9 * 10]])
    q = critic_target(jnp.array([1.0, 1.0]), termination[0], jnp.array([[10.0, 12.0], [10.0, 12.0]]),
                      jnp.zeros(2), 0.0, 0.9, 1.0)
    np.testing.assert_allclose(np.asarray(q), [1.0, 10.0])


def test_ppo_loss_on_hand_computed_numbers():
    log_prob = jnp.log(jnp.array([1.5, 0.5, 1.1, 0.7]))  # ratios 1.5, 0.5, 1.1, 0.7 (old log-prob 0)
    old = jnp.zeros(4)
    adv = jnp.array([1.0, 1.0, -2.0, -2.0])
    values, targets = jnp.array([0.0, 1.0, 2.0, 3.0]), jnp.array([1.0, 1.0, 0.0, 3.0])
    terms = ppo_loss_terms(log_prob, old, adv, values, targets, jnp.array([0.5, 0.5, 0.5, 0.5]), 0.2)
    # min(r A, clip(r, 0.8, 1.2) A): min(1.5, 1.2) = 1.2; min(0.5, 0.8) = 0.5; -2.2 (inside the range);
    # min(-1.4, -1.6) = -1.6 (the clipped term is the pessimistic one) -> mean -0.525
    assert float(terms["policy_loss"]) == pytest.approx(0.525, rel=1e-6)
    assert float(terms["value_loss"]) == pytest.approx((1 + 0 + 4 + 0) / 4, rel=1e-6)
    assert float(terms["clip_fraction"]) == pytest.approx(0.75)
    kl = np.mean([(r - 1) - math.log(r) for r in (1.5, 0.5, 1.1, 0.7)])
    assert float(terms["approx_kl"]) == pytest.approx(kl, rel=1e-5)


def test_ppo_loss_method_weights_the_terms_and_names_its_metrics():
    """PPO.loss = policy loss + value_loss_coef * value loss - entropy_coef * entropy, on the
    networks' outputs, with the value targets normalised by the value statistics."""
    config = PPOConfig(num_envs=4, batch_size=4, num_minibatches=1, policy_hidden_sizes=(8,), value_hidden_sizes=(8,),
                       value_loss_coef=0.25, entropy_coef=0.01, clip_epsilon=0.2)
    ppo = PPO(config, 3, 2, 10)
    state = ppo.init(jax.random.PRNGKey(0))
    stats = normalizer.RunningStats(jnp.array(10.0), jnp.array(2.0), jnp.array(4.0))  # mean 2, std 2
    rng = np.random.default_rng(0)
    mb = {"obs": jnp.asarray(rng.normal(size=(4, 3)), jnp.float32),
          "raw_action": jnp.asarray(rng.normal(size=(4, 2)), jnp.float32),
          "log_prob": jnp.asarray(rng.normal(size=4), jnp.float32),
          "advantages": jnp.array([1.0, -1.0, 0.5, 2.0]), "targets": jnp.array([2.0, 4.0, 0.0, 6.0]),
          "noise": jnp.asarray(rng.normal(size=(4, 2)), jnp.float32)}
    loss, metrics = ppo.loss(state.params, mb, stats)
    dist = TanhNormal.from_network_output(ppo.policy_net.apply(state.params["policy"], mb["obs"]), config.min_std)
    values = ppo.value_net.apply(state.params["value"], mb["obs"])[..., 0]
    terms = ppo_loss_terms(dist.log_prob_raw(mb["raw_action"]), mb["log_prob"], mb["advantages"], values,
                           jnp.array([0.0, 1.0, -1.0, 2.0]), dist.entropy_from_noise(mb["noise"]), 0.2)
    expected = terms["policy_loss"] + 0.25 * terms["value_loss"] - 0.01 * terms["entropy"]
    assert float(loss) == pytest.approx(float(expected), rel=1e-5)
    assert float(metrics["loss/value"]) == pytest.approx(float(terms["value_loss"]), rel=1e-5)
    assert float(metrics["policy/entropy"]) == pytest.approx(float(terms["entropy"]), rel=1e-5)
    assert float(metrics["loss/total"]) == float(loss)


def test_learning_rate_schedules():
    cfg = PPOConfig(learning_rate=1.0, lr_end_fraction=0.1)
    assert float(learning_rate(cfg, jnp.array(0.5))) == pytest.approx(0.55)
    assert float(learning_rate(cfg.__class__(learning_rate=1.0, lr_schedule="cosine", lr_end_fraction=0.0), jnp.array(0.5))) == pytest.approx(0.5)
    assert float(learning_rate(cfg.__class__(learning_rate=2.0, lr_schedule="constant"), jnp.array(0.9))) == 2.0


def test_progress_note_for_runs_stopped_before_their_schedule_ends():
    """train.py's closing line for a PPO run cut short: 160 of 916 updates done under a linear
    schedule to 10 % -> 1 - 0.9 * 160 / 916 = 84.3 % of the start rate."""
    from agents.sac import SAC, SACConfig

    ppo = PPO(PPOConfig(), 7, 3, 916)
    note = ppo.progress_note(160)
    assert note.startswith("the learning rate is at 84% of its start")
    assert "916 updates (160 done)" in note
    assert ppo.progress_note(916) is None  # the schedule's last update is done
    assert PPO(PPOConfig(lr_schedule="constant"), 7, 3, 916).progress_note(160) is None
    assert SAC(SACConfig(), 7, 3).progress_note(10) is None


def test_popart_preserves_value_outputs():
    net = MLP((8,), 1)
    params = net.init(jax.random.PRNGKey(0), jnp.zeros((1, 3)))
    x = jax.random.normal(jax.random.PRNGKey(1), (5, 3))
    old = normalizer.RunningStats(jnp.array(10.0), jnp.array(2.0), jnp.array(4.0))
    new = normalizer.RunningStats(jnp.array(20.0), jnp.array(-1.0), jnp.array(0.25))
    before = normalizer.denormalize(old, net.apply(params, x))
    after = normalizer.denormalize(new, net.apply(popart_preserve(params, old, new), x))
    np.testing.assert_allclose(np.asarray(after), np.asarray(before), rtol=1e-5, atol=1e-5)


def test_advantages_are_standardised_per_minibatch_and_over_devices():
    adv = jnp.array([[1.0, 3.0], [2.0, 2.0], [0.0, 4.0]])  # 3 minibatches of 2: means 2, stds 1, 0, 2
    out = np.asarray(normalize_per_minibatch(adv))
    np.testing.assert_allclose(out, [[-1.0, 1.0], [0.0, 0.0], [-1.0, 1.0]], atol=1e-6)
    # Each minibatch split over two devices (one element each): the statistics are the whole minibatch's.
    split = jnp.stack([adv[:, :1], adv[:, 1:]])
    per_device = jax.vmap(lambda a: normalize_per_minibatch(a, lambda x: jax.lax.pmean(x, "d")), axis_name="d")(split)
    np.testing.assert_allclose(np.concatenate(np.asarray(per_device), axis=1), out, atol=1e-6)


def test_ppo_minibatches_are_a_stratified_permutation():
    cfg = PPOConfig(num_envs=4, batch_size=4, num_minibatches=4, unroll_length=2)
    ppo = PPO(cfg, 3, 1, 10)
    ids = jnp.arange(4 * 4).reshape(4, 4)  # (envs, unrolls): unroll id
    mbs = ppo.minibatches({"id": ids}, jax.random.PRNGKey(0), Parallel(4))["id"]
    assert mbs.shape == (4, 4)
    assert sorted(np.asarray(mbs).ravel().tolist()) == list(range(16))
    for mb in np.asarray(mbs):  # every minibatch takes one unroll from each env
        assert sorted((mb // 4).tolist()) == [0, 1, 2, 3]


# -- SAC ----------------------------------------------------------------------------------------


def test_sac_critic_target_on_hand_computed_numbers():
    reward = jnp.array([1.0, 0.5])
    termination = jnp.array([0.0, 1.0])
    next_q = jnp.array([[3.0, 2.0], [5.0, 7.0]])
    next_log_prob = jnp.array([-1.0, 0.4])
    y = critic_target(reward, termination, next_q, next_log_prob, alpha=0.2, discount=0.9, reward_scaling=20.0)
    # env 0: 20 * 1 + 0.9 * (min(3, 2) - 0.2 * -1) = 20 + 0.9 * 2.2 = 21.98; env 1 terminated: 10
    np.testing.assert_allclose(np.asarray(y), [21.98, 10.0], rtol=1e-6)
    q = jnp.array([[21.0, 22.98], [10.0, 11.0]])
    assert float(critic_loss(q, y)) == pytest.approx(0.5 * (0.98**2 + 1.0**2 + 0 + 1.0) / 4, rel=1e-5)
    assert float(actor_loss(jnp.array([-1.0, 0.5]), jnp.array([[1.0, 2.0], [3.0, 0.0]]), 0.1)) == pytest.approx(
        ((0.1 * -1 - 1.0) + (0.1 * 0.5 - 0.0)) / 2, rel=1e-6)


def test_sac_temperature_update_on_hand_computed_numbers():
    log_alpha = jnp.array(math.log(0.5))
    log_prob = jnp.array([-0.5, 0.5, 1.0])  # entropy -mean = -1/3
    target_entropy = -2.0
    loss, grad = jax.value_and_grad(temperature_loss)(log_alpha, log_prob, target_entropy)
    # d/dlog_alpha = -(mean(log pi) + target) = -(1/3 - 2) = 5/3 > 0: entropy above target, alpha falls.
    assert float(grad) == pytest.approx(5.0 / 3.0, rel=1e-6)
    assert float(loss) == pytest.approx(-math.log(0.5) * (1.0 / 3.0 - 2.0), rel=1e-6)
    opt = optax.adam(1e-2)
    updates, _ = opt.update(grad, opt.init(log_alpha), log_alpha)
    # Adam's first step is lr * g / (|g| + eps) = -lr * sign(g).
    assert float(optax.apply_updates(log_alpha, updates)) == pytest.approx(math.log(0.5) - 1e-2, rel=1e-5)
    target = polyak({"w": jnp.array(1.0)}, {"w": jnp.array(3.0)}, 0.005)
    assert float(target["w"]) == pytest.approx(1.01)
    # The entropy target: -action_size unless the config names one (Brax's -0.5 * action_size learned slower).
    assert SAC(SACConfig(), observation_size=4, action_size=6).target_entropy == -6.0
    assert SAC(SACConfig(target_entropy=-3.0), observation_size=4, action_size=6).target_entropy == -3.0


def test_twin_q_and_mlp_shapes():
    q = TwinQ((16, 16))
    params = q.init(jax.random.PRNGKey(0), jnp.zeros((1, 5)), jnp.zeros((1, 2)))
    out = q.apply(params, jnp.ones((7, 5)), jnp.ones((7, 2)))
    assert out.shape == (7, 2)
    assert not np.allclose(np.asarray(out[:, 0]), np.asarray(out[:, 1]))  # independent critics
    assert len(params["params"]["q0"]) == 3  # two hidden layers + output
