"""agents/offpolicy.py on hand-computed numbers and against plain-Python loops (no training)."""

import math

import jax
import jax.numpy as jnp
import numpy as np
import pytest

from agents.offpolicy import (categorical_cross_entropy, categorical_mean, categorical_projection, categorical_support,
                              gather_nstep, nstep_targets)

# -- categorical critic -----------------------------------------------------------------------


def test_categorical_support():
    np.testing.assert_allclose(np.asarray(categorical_support(-2.0, 2.0, 5)), [-2, -1, 0, 1, 2])
    np.testing.assert_allclose(np.asarray(categorical_support(0.0, 1.0, 3)), [0, 0.5, 1])
    with pytest.raises(ValueError, match="num_atoms=1"):
        categorical_support(0.0, 1.0, 1)


def test_projection_on_hand_computed_numbers():
    support = categorical_support(-2.0, 2.0, 5)  # dz = 1; b_j = T z_j + 2
    p = [0.1, 0.2, 0.3, 0.3, 0.1]
    rewards = jnp.array([0.25, 1.5, -1.5, 0.5, 0.0, 0.0, 0.3])
    discounts = jnp.array([0.5, 1.0, 1.0, 1.5, 1.0, 0.5, 0.0])
    out = np.asarray(categorical_projection(jnp.array([p] * 7), rewards, discounts, support))
    expected = [
        # r 0.25, d 0.5: T z = -0.75, -0.25, 0.25, 0.75, 1.25 -> b = 1.25, 1.75, 2.25, 2.75, 3.25, all between atoms:
        # atom 1: .1*.75 + .2*.25 = .125; atom 2: .1*.25 + .2*.75 + .3*.75 + .3*.25 = .475;
        # atom 3: .3*.25 + .3*.75 + .1*.75 = .375; atom 4: .1*.25 = .025
        [0.0, 0.125, 0.475, 0.375, 0.025],
        # r 1.5, d 1: T z = -0.5, 0.5, 1.5, 2.5, 3.5, the last two clipped to v_max = 2 -> b = 1.5, 2.5, 3.5, 4, 4:
        # atom 1 .05; atom 2 .05 + .1; atom 3 .1 + .15; atom 4 .15 + .3 + .1
        [0.0, 0.05, 0.15, 0.25, 0.55],
        # r -1.5, d 1: T z = -3.5, -2.5, -1.5, -0.5, 0.5, the first two clipped to v_min -> b = 0, 0, .5, 1.5, 2.5:
        # atom 0 .1 + .2 + .15; atom 1 .15 + .15; atom 2 .15 + .05; atom 3 .05
        [0.45, 0.3, 0.2, 0.05, 0.0],
        # r 0.5, d 1.5 (> 1 only to clip both ends in one sample): T z = -2.5, -1, 0.5, 2, 3.5 -> b = 0, 1, 2.5, 4, 4
        [0.1, 0.2, 0.15, 0.15, 0.4],
        # r 0, d 1: every T z_j is exactly atom j (l == u in Algorithm 1): the distribution is unchanged
        p,
        # r 0, d 0.5: T z = -1, -0.5, 0, 0.5, 1 -> b = 1, 1.5, 2, 2.5, 3: atom 1 .1 + .1; atom 2 .1 + .3 + .15; atom 3 .15 + .1
        [0.0, 0.2, 0.55, 0.25, 0.0],
        # terminal (d 0): all mass at r = 0.3 -> b = 2.3: atom 2 gets 0.7, atom 3 gets 0.3, whatever p is
        [0.0, 0.0, 0.7, 0.3, 0.0],
    ]
    np.testing.assert_allclose(out, expected, atol=1e-6)
    np.testing.assert_allclose(out.sum(-1), 1.0, atol=1e-6)


def _project_loop(p, r, d, z):
    """Bellemare et al. 2017, Algorithm 1, one sample at a time in float64; l == u gets the whole p_j."""
    num_atoms, v_min, v_max = len(z), z[0], z[-1]
    dz = (v_max - v_min) / (num_atoms - 1)
    m = np.zeros(num_atoms)
    for j in range(num_atoms):
        tz = min(max(r + d * z[j], v_min), v_max)
        b = (tz - v_min) / dz
        lower, upper = math.floor(b), math.ceil(b)
        if lower == upper:
            m[lower] += p[j]
        else:
            m[lower] += p[j] * (upper - b)
            m[upper] += p[j] * (b - lower)
    return m


def test_projection_matches_plain_loop_on_random_inputs():
    rng = np.random.default_rng(0)
    z = np.linspace(-5.0, 5.0, 11)
    shape = (3, 8)  # any leading axes
    p = rng.dirichlet(np.ones(11), size=shape)
    r = rng.uniform(-8, 8, size=shape)
    d = rng.uniform(0, 1, size=shape)
    d[0, :3] = 0.0  # terminal
    r[1, :4], d[1, :4] = rng.integers(-6, 7, size=4), 1.0  # on atoms (and clipped past the ends)
    r[2, :2], d[2, :2] = 0.5, 0.0  # terminal, halfway between two atoms
    out = np.asarray(jax.jit(categorical_projection)(*(jnp.asarray(a, jnp.float32) for a in (p, r, d, z))))
    assert out.shape == shape + (11,)
    for idx in np.ndindex(*shape):
        np.testing.assert_allclose(out[idx], _project_loop(p[idx], r[idx], d[idx], z), atol=1e-5, err_msg=str(idx))
    np.testing.assert_allclose(out.sum(-1), 1.0, atol=1e-5)


def test_projection_keeps_the_mean_when_nothing_is_clipped():
    # Linear interpolation between neighbouring atoms preserves the expectation: E = r + d E[Z'].
    z = categorical_support(-10.0, 10.0, 21)
    p = jnp.array([[0.2, 0.5, 0.3] + [0.0] * 18])  # on atoms -10, -9, -8: mean -8.9
    out = categorical_projection(p, jnp.array([3.3]), jnp.array([0.9]), z)  # to -5.7, -4.8, -3.9, between atoms
    # 3.3 + 0.9 * -8.9 = -4.71
    assert float(categorical_mean(out, z, is_logits=False)[0]) == pytest.approx(-4.71, rel=1e-5)
    assert np.count_nonzero(np.asarray(out)) == 4  # atoms -6, -5, -4, -3 and no other


def test_cross_entropy_and_mean_on_hand_computed_numbers():
    probs = np.array([0.5, 0.25, 0.25])
    logits = jnp.log(jnp.asarray(probs)) + 3.0  # a constant shift leaves the softmax unchanged
    support = jnp.array([-1.0, 0.0, 1.0])
    target = jnp.array([[0.0, 1.0, 0.0], [0.5, 0.5, 0.0]])
    loss = categorical_cross_entropy(jnp.stack([logits, logits]), target)
    # -log 0.25 = 2 log 2; -(0.5 log 0.5 + 0.5 log 0.25) = 1.5 log 2
    np.testing.assert_allclose(np.asarray(loss), [2 * math.log(2), 1.5 * math.log(2)], rtol=1e-6)
    # 0.5 * -1 + 0.25 * 0 + 0.25 * 1 = -0.25, from logits and from probabilities
    assert float(categorical_mean(logits, support, is_logits=True)) == pytest.approx(-0.25, abs=1e-6)
    assert float(categorical_mean(jnp.asarray(probs), support, is_logits=False)) == pytest.approx(-0.25, abs=1e-6)
    assert categorical_mean(jnp.zeros((4, 2, 3)), support, is_logits=True).shape == (4, 2)


def test_cross_entropy_gradient_is_softmax_minus_target():
    logits = jnp.array([[0.3, -1.2, 2.0, 0.1], [1.0, 1.0, -0.5, 0.0]])
    target = jnp.array([[0.1, 0.2, 0.3, 0.4], [0.0, 0.0, 1.0, 0.0]])
    g_logits, g_target = jax.grad(lambda l, t: jnp.sum(categorical_cross_entropy(l, t)), argnums=(0, 1))(logits, target)
    np.testing.assert_allclose(np.asarray(g_logits), np.asarray(jax.nn.softmax(logits) - target), atol=1e-6)
    # Hand numbers for the first row's first entry: softmax_0 - 0.1.
    e = np.exp([0.3, -1.2, 2.0, 0.1])
    assert float(g_logits[0, 0]) == pytest.approx(e[0] / e.sum() - 0.1, rel=1e-5)
    np.testing.assert_array_equal(np.asarray(g_target), 0.0)  # the target is a constant


# -- n-step returns ---------------------------------------------------------------------------


def _nstep_loop(r, term, trunc, gamma, n):
    """For one env: (R_t, bootstrap discount, offset) by walking each window step by step."""
    T = len(r)
    out = np.zeros((3, T))
    for t in range(T):
        ret, m, terminated = 0.0, 0, 0.0
        for k in range(n):
            if t + k >= T:
                break
            ret += gamma**k * r[t + k]
            m += 1
            if term[t + k]:
                terminated = 1.0
                break
            if trunc[t + k]:
                break
        out[:, t] = ret, gamma**m * (1.0 - terminated), m - 1
    return out


def test_nstep_on_hand_computed_numbers():
    # One env, gamma 0.5, n 3: termination at step 1, truncation at step 3, the array ends after step 5.
    r = jnp.array([1.0, 2.0, 3.0, 4.0, 5.0, 6.0])
    term = jnp.array([0.0, 1.0, 0.0, 0.0, 0.0, 0.0])
    trunc = jnp.array([0.0, 0.0, 0.0, 1.0, 0.0, 0.0])
    returns, bootstrap, offsets = nstep_targets(r, term, trunc, 0.5, 3)
    # t0: steps 0, 1 (terminated) -> 1 + .5 * 2 = 2, no bootstrap; t1: 2, none; t2: steps 2, 3 (truncated) ->
    # 3 + .5 * 4 = 5, bootstrap .25 from next_obs[3]; t3: 4, .5; t4: steps 4, 5 (array ends) -> 5 + 3 = 8, .25; t5: 6, .5
    np.testing.assert_allclose(np.asarray(returns), [2, 2, 5, 4, 8, 6])
    np.testing.assert_allclose(np.asarray(bootstrap), [0, 0, 0.25, 0.5, 0.25, 0.5])
    np.testing.assert_array_equal(np.asarray(offsets), [1, 0, 1, 0, 1, 0])
    assert offsets.dtype == jnp.int32
    next_obs = jnp.arange(6.0)[:, None, None] * jnp.ones((1, 1, 2))  # (T, envs, obs): next_obs[t] = t
    boot_obs = gather_nstep(next_obs, offsets[:, None])
    np.testing.assert_array_equal(np.asarray(boot_obs[:, 0, 0]), [1, 1, 3, 3, 5, 5])
    assert boot_obs.shape == (6, 1, 2)


@pytest.mark.parametrize("n", [1, 3])
def test_nstep_matches_plain_loop_on_random_episodes(n):
    rng = np.random.default_rng(n)
    T, E, gamma = 12, 5, 0.9
    r = rng.normal(size=(T, E))
    term, trunc = np.zeros((T, E)), np.zeros((T, E))
    term[4, 0] = trunc[6, 0] = 1  # env 0: a termination, then a truncation two steps later (both inside windows)
    trunc[2, 1] = term[3, 1] = 1  # env 1: a truncation right before a termination
    term[T - 1, 2] = 1  # env 2: terminates on the array's last step
    trunc[T - 2, 3] = 1  # env 3: truncated one step before the end
    term[:, 4] = rng.random(T) < 0.2  # env 4: random
    trunc[:, 4] = (rng.random(T) < 0.2) * (1 - term[:, 4])
    step = jax.jit(nstep_targets, static_argnums=4)  # discount traced
    returns, bootstrap, offsets = step(*(jnp.asarray(a, jnp.float32) for a in (r, term, trunc)), jnp.float32(gamma), n)
    for e in range(E):
        ref = _nstep_loop(r[:, e], term[:, e], trunc[:, e], gamma, n)
        np.testing.assert_allclose(np.asarray(returns)[:, e], ref[0], rtol=1e-5, atol=1e-6, err_msg=f"env {e}")
        np.testing.assert_allclose(np.asarray(bootstrap)[:, e], ref[1], rtol=1e-5, atol=1e-7, err_msg=f"env {e}")
        np.testing.assert_array_equal(np.asarray(offsets)[:, e], ref[2], err_msg=f"env {e}")
    if n == 1:  # one step: (r, gamma (1 - termination), 0)
        np.testing.assert_allclose(np.asarray(returns), r, rtol=1e-6)
        np.testing.assert_allclose(np.asarray(bootstrap), gamma * (1 - term), rtol=1e-6)
        np.testing.assert_array_equal(np.asarray(offsets), 0)
    else:  # the windows are cut where expected
        assert np.asarray(offsets)[:, 0].tolist()[2:7] == [2, 1, 0, 1, 0]
        assert np.asarray(offsets)[T - 3:, 2].tolist() == [2, 1, 0]


def test_nstep_rejects_n_below_one():
    with pytest.raises(ValueError, match="n=0"):
        nstep_targets(jnp.ones(3), jnp.zeros(3), jnp.zeros(3), 0.9, 0)
