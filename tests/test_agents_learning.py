"""PPO and SAC learn the point-mass probe; the loop records truncation vs termination correctly;
vmapped seeds are independent runs."""


import jax
import jax.numpy as jnp
import numpy as np
import pytest

import envs
from agents import driver, presets
from agents.loop import Programs, Transition

SHORT = 30_720  # 6 PPO updates of the probe preset; shared with tests/test_loop_train.py (same compiled program)


def _random_policy_baseline(num_envs=256):
    """Mean return and target-reached rate of uniform random actions on the probe task."""
    env = envs.wrap(envs.make("point-mass"))

    @jax.jit
    def run(key):
        k_reset, k_act = jax.random.split(key)
        state = env.reset(jax.random.split(k_reset, num_envs))

        def step(carry, k):
            s, alive, ret, reached = carry
            nxt = env.step(s, jax.random.uniform(k, (num_envs, env.action_size), minval=-1, maxval=1))
            ret = ret + alive * nxt.reward
            reached = jnp.where(alive * nxt.done > 0, nxt.metrics["target_reached"], reached)
            return (nxt, alive * (1 - nxt.done), ret, reached), None

        init = (state, jnp.ones(num_envs), jnp.zeros(num_envs), jnp.zeros(num_envs))
        (_, _, ret, reached), _ = jax.lax.scan(step, init, jax.random.split(k_act, 50))
        return jnp.mean(ret), jnp.mean(reached)

    return [float(x) for x in run(jax.random.PRNGKey(0))]


@pytest.fixture(scope="module")
def random_baseline():
    return _random_policy_baseline()


def _solve(preset, tmp_path):
    result = driver.train(presets.make_config(preset, logdir=str(tmp_path / preset), tensorboard=False, progress=False))
    return {k: float(np.mean(v)) for k, v in result.eval_metrics.items()}


@pytest.mark.parametrize("preset", ["point-mass-ppo", "point-mass-sac"])
def test_learner_solves_point_mass_probe(preset, tmp_path, random_baseline):
    random_return, random_reached = random_baseline
    assert random_return < 5
    assert random_reached < 0.3  # the task is not trivial
    ev = _solve(preset, tmp_path)
    assert ev["episode/target_reached"] >= 0.95
    assert ev["episode/return"] > max(30.0, 5 * random_return)
    assert ev["episode/distance"] < 0.05


class _Recorder:
    """A learner that pushes every action to +1 and keeps the last batch of transitions."""

    steps_per_update = 6

    def __init__(self, obs_size, action_size, num_envs):
        self.shape = (self.steps_per_update, num_envs)
        self.obs_size, self.action_size = obs_size, action_size

    def init(self, key):
        z = lambda *s: jnp.zeros(self.shape + s)
        return Transition(z(self.obs_size), z(self.action_size), z(), z(), z(), z(self.obs_size), {})

    def env_axes(self, state):
        return jax.tree.map(lambda _: 1, state)

    def act(self, state, obs, key, par):
        return jnp.ones((obs.shape[0], self.action_size)), {}

    def update(self, state, batch, key, par):
        return batch, {"loss/none": jnp.zeros(())}

    def policy(self, state, obs):
        return jnp.ones((obs.shape[0], self.action_size))


def test_loop_keeps_terminal_obs_and_separates_truncation_from_termination():
    cfg = envs.make_config("point-mass", episode_length=3, arena=1.05)
    env = envs.wrap(envs.from_config("point-mass", cfg))
    learner = _Recorder(env.observation_size, env.action_size, 32)
    programs = Programs(env, env, learner, 32, 1, jax.devices()[:1], 4, 3)
    state = programs.init(jnp.stack([jax.random.PRNGKey(3)]))
    state, _ = programs.chunk(state, jnp.int32(2))  # second batch: episodes already mid-way
    b = jax.tree.map(lambda x: np.asarray(x[0]), state.learner)
    pos, next_pos = b.obs[..., :2], b.next_obs[..., :2]
    # next_obs is the result of this step's action, also on done steps (the terminal observation) ...
    np.testing.assert_allclose(next_pos, np.clip(pos + 0.1, None, None), atol=1e-5)
    done = np.maximum(b.termination, b.truncation)
    assert np.all(b.termination * b.truncation == 0)
    # ... while the following step starts from a fresh episode there.
    assert np.all(np.abs(b.obs[1:] - b.next_obs[:-1]).max(-1)[done[:-1] > 0] > 1e-3)
    np.testing.assert_allclose(b.obs[1:][done[:-1] == 0], b.next_obs[:-1][done[:-1] == 0])
    outside = (np.abs(next_pos) > 1.05).any(-1)
    np.testing.assert_array_equal(b.termination, outside.astype(np.float32))  # real terminations only
    assert b.truncation.sum() > 5
    assert b.termination.sum() > 5  # both kinds occur in this batch


def test_vmapped_seeds_are_independent_and_match_single_seed_runs(tmp_path):
    # Two updates: vmapped and single runs differ only by float rounding (batched matmuls), which
    # chaotic training amplifies over longer runs (1e-7 after 2 updates, 1e-3 after 6).
    # On GPUs, TF32 matmuls would round batched and unbatched products differently: use full float32.
    precision = "highest" if jax.default_backend() == "gpu" else "default"
    base = dict(num_timesteps=SHORT, stop_after_steps=10_240, eval_envs=0, tensorboard=False, progress=False,
                matmul_precision=precision)
    both = driver.train(presets.make_config("point-mass-ppo", seeds=2, logdir=str(tmp_path / "both"), **base))
    singles = [driver.train(presets.make_config("point-mass-ppo", seed=s, logdir=str(tmp_path / f"s{s}"), **base))
               for s in (0, 1)]
    p_both = [jax.tree.map(lambda x, i=i: np.asarray(x[i]), jax.device_get(both.state.learner.params)) for i in (0, 1)]
    p_single = [jax.tree.map(lambda x: np.asarray(x[0]), jax.device_get(r.state.learner.params)) for r in singles]
    for i in (0, 1):
        for a, b in zip(jax.tree.leaves(p_both[i]), jax.tree.leaves(p_single[i])):
            np.testing.assert_allclose(a, b, rtol=1e-4, atol=1e-5)
    assert all(int(r.state.updates[0]) == 2 for r in singles)
    diff = max(np.max(np.abs(a - b)) for a, b in zip(jax.tree.leaves(p_both[0]), jax.tree.leaves(p_both[1])))
    assert diff > 1e-2  # different seeds, different runs
    # Episode statistics are per seed too.
    assert both.last_metrics["episode/return"][0] != both.last_metrics["episode/return"][1]
