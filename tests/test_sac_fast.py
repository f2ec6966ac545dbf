"""Fast SAC's switches (agents/sac.py: n-step returns from the buffer, the categorical critic),
its probe preset and its checkpoints without the replay buffer."""

import dataclasses
import json
import os
import subprocess
import sys
import textwrap

import jax
import jax.numpy as jnp
import numpy as np
import pytest

from agents import driver, presets
from agents.loop import Parallel, Transition
from agents.networks import TwinQ, unstack_twin_params
from agents.replay import Replay
from agents.sac import SAC, SACConfig
from limits import HANG_GUARD_S

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))


def _plain_nstep(rewards, terms, truncs, t, e, gamma, n):
    """n-step return, bootstrap discount and bootstrap row of transition (t, e), by hand."""
    ret, k = 0.0, 0
    while True:
        ret += gamma**k * rewards[t + k, e]
        if terms[t + k, e]:
            return ret, 0.0, t + k
        if truncs[t + k, e] or k == n - 1:
            return ret, gamma ** (k + 1), t + k
        k += 1


def test_nstep_samples_from_the_buffer_match_a_plain_loop():
    """A buffer of 9 rows x 4 envs filled with 11 steps (so it wrapped), terminations and time-outs
    inside; every sampled transition's 3-step return, discount, bootstrap observation and failure cost (the
    discounted terminations) agree with a plain-Python walk over the steps in time order, and no window reaches past
    the newest row."""
    n, gamma, num_envs, steps = 3, 0.9, 4, 11
    config = SACConfig(num_envs=num_envs, batch_size=64, max_replay_size=9 * num_envs, min_replay_size=0, n_step=n,
                       discount=gamma)
    sac = SAC(config, 2, 1)
    rng = np.random.default_rng(0)
    rewards = rng.normal(size=(steps, num_envs)).astype(np.float32)
    terms = np.zeros((steps, num_envs), np.float32)
    truncs = np.zeros((steps, num_envs), np.float32)
    terms[4, 0] = terms[8, 2] = terms[9, 1] = terms[7, 3] = 1  # env 3 fails in the step after a time-out
    truncs[5, 1] = truncs[6, 3] = truncs[9, 0] = 1
    # Observations say which (step, env) they belong to; next_obs is marked with + 0.5.
    ids = np.stack(np.meshgrid(np.arange(steps), np.arange(num_envs), indexing="ij"), -1).astype(np.float32)
    replay = sac.init(jax.random.PRNGKey(0)).replay
    for t in range(steps):
        tr = Transition(obs=jnp.asarray(ids[t:t + 1]), action=jnp.zeros((1, num_envs, 1)),
                        reward=jnp.asarray(rewards[t:t + 1]), termination=jnp.asarray(terms[t:t + 1]),
                        truncation=jnp.asarray(truncs[t:t + 1]), next_obs=jnp.asarray(ids[t:t + 1] + 0.5), extras={})
        replay = sac.insert(replay, tr)
    seen = set()
    for k in range(8):
        mb, _ = sac.sample(replay, jax.random.PRNGKey(k), Parallel(num_envs))
        for obs, ret, disc, nxt, cost in zip(*(np.asarray(mb[key])
                                               for key in ("obs", "reward", "discount", "next_obs", "cost"))):
            t, e = int(obs[0]), int(obs[1])
            assert 2 <= t <= steps - n  # rows 0-1 were overwritten; the newest n - 1 rows start no window
            expected = _plain_nstep(rewards, terms, truncs, t, e, gamma, n)
            assert ret == pytest.approx(expected[0], abs=1e-5)
            assert disc == pytest.approx(expected[1], abs=1e-6)
            np.testing.assert_array_equal(nxt, [expected[2] + 0.5, e + 0.5])
            assert cost == pytest.approx(_plain_nstep(terms, terms, truncs, t, e, gamma, n)[0], abs=1e-6)
            seen.add((t, e))
    assert len(seen) > 20  # the samples spread over the buffer


def test_distributional_target_of_a_terminal_transition_is_its_reward():
    """With discount 0 (terminated at the first step) the projected target puts all mass around the
    reward: r = 1.25 on atoms [-5, -2.5, 0, 2.5, 5, ...] -> 0.5 on 0 and 0.5 on 2.5."""
    config = SACConfig(num_envs=4, batch_size=4, distributional=True, num_atoms=5, v_min=-5.0, v_max=5.0, reward_scaling=1.0,
                       q_hidden_sizes=(8,), policy_hidden_sizes=(8,))
    sac = SAC(config, 3, 2)
    state = sac.init(jax.random.PRNGKey(0))
    mb = {"reward": jnp.full(4, 1.25), "discount": jnp.array([0.0, 0.0, 0.0, 0.97])}
    target = sac.critic_target(state, mb, jnp.zeros((4, 3)), jnp.zeros((4, 2)), 0.5)
    np.testing.assert_allclose(np.asarray(target[:3]), [[0, 0, 0.5, 0.5, 0]] * 3, atol=1e-6)
    np.testing.assert_allclose(np.asarray(target.sum(-1)), 1.0, atol=1e-6)
    assert float(jnp.abs(target[3] - target[0]).sum()) > 0.1  # a bootstrapped one spreads further


def test_fast_sac_probe_learns_the_point_mass():
    result = driver.train(presets.make_config("point-mass-sac-fast", tensorboard=False, progress=False,
                                              logdir=""), )
    assert result.status == "done"
    assert np.mean(result.eval_metrics["episode/target_reached"]) > 0.9


def test_fast_sac_saves_without_its_buffer_and_resumes(tmp_path):
    """Fast presets keep the buffer out of checkpoints: a stopped run resumes from the learner,
    refills min_replay_size random transitions and finishes."""
    base = dict(num_timesteps=6_400, eval_envs=0, tensorboard=False, progress=False, logdir=str(tmp_path / "run"))
    config = presets.make_config("point-mass-sac-fast", stop_after_steps=3_200, **base)
    assert config.checkpoint_envs is False
    first = driver.train(config)
    assert first.status == "stopped"
    assert first.env_steps == 3_200
    resumed = driver.train(presets.make_config("point-mass-sac-fast", resume=True, **base))
    assert resumed.status == "done"
    assert resumed.env_steps == 6_400
    # The resumed learner continued from the saved one (same temperature trajectory start), and the
    # buffer was refilled: the last chunk trained (losses non-zero).
    assert np.all(np.asarray(resumed.last_metrics["loss/critic"]) != 0)


@pytest.mark.parametrize("field, value, message", [
    ("n_step", 0, r"algo.n_step=0 is invalid: allowed is an integer >= 1"),
    ("num_atoms", 1, r"algo.num_atoms=1 is invalid: allowed is an integer >= 2"),
    ("v_min", float("nan"), r"algo.v_min=nan is invalid: allowed is a finite number"),
    ("v_max", -20.0, r"algo.v_max=-20.0 is invalid: allowed is a number > algo.v_min=-10.0"),
    ("max_replay_size", 128, r"algo.max_replay_size=128 is invalid with algo.n_step=3"),
    ("compute_dtype", "float16", r"algo.compute_dtype='float16' is invalid: allowed are 'float32', 'bfloat16'"),
    ("stacked_critics", 1, r"algo.stacked_critics=1 is invalid: allowed are True, False"),
])
def test_fast_sac_fields_reject_bad_values(field, value, message):
    config = dataclasses.replace(SACConfig(num_envs=64, batch_size=64, n_step=3, min_replay_size=0), **{field: value})
    with pytest.raises(ValueError, match=message):
        config.validate()


def test_bfloat16_networks_compute_in_bf16_and_keep_float32_parameters_and_outputs():
    """The same parameters through the float32 and the bfloat16 critics and policy: outputs float32, close to
    float32's within bf16's ~3 significant digits, and not identical (the matmuls did run in bf16)."""
    kw = dict(num_envs=4, batch_size=4, distributional=True, num_atoms=11, layer_norm=True, q_hidden_sizes=(64, 64))
    f32 = SAC(SACConfig(**kw), observation_size=7, action_size=3)
    bf16 = SAC(SACConfig(**kw, compute_dtype="bfloat16"), observation_size=7, action_size=3)
    obs = jax.random.normal(jax.random.PRNGKey(0), (256, 7))
    act = jax.random.uniform(jax.random.PRNGKey(1), (256, 3), minval=-1, maxval=1)
    q_params = f32.q_net.init(jax.random.PRNGKey(2), obs, act)
    assert jax.tree.leaves(bf16.q_net.init(jax.random.PRNGKey(2), obs, act))[0].dtype == jnp.float32
    for net32, net16, params, args in ((f32.q_net, bf16.q_net, q_params, (obs, act)),
                                       (f32.policy_net, bf16.policy_net, f32.policy_net.init(jax.random.PRNGKey(3), obs), (obs,))):
        a, b = net32.apply(params, *args), net16.apply(params, *args)
        assert a.dtype == b.dtype == jnp.float32
        assert a.shape == b.shape
        scale = float(jnp.abs(a).max())
        assert float(jnp.abs(a - b).max()) < 0.03 * scale
        assert float(jnp.abs(a - b).max()) > 1e-4 * scale


def test_throughput_benchmark_variants_parse_and_name_unknown_fields():
    from benchmarks.train_throughput import parse_variant

    algo = SACConfig()
    assert parse_variant("compute_dtype=bfloat16,q_hidden_sizes=(512, 512, 256),tau=0.05", algo) == {
        "compute_dtype": "bfloat16", "q_hidden_sizes": (512, 512, 256), "tau": 0.05}
    assert parse_variant("grad-updates-per-step=2", algo) == {"grad_updates_per_step": 2}
    with pytest.raises(ValueError, match="'unroll_length' is not a field of SACConfig"):
        parse_variant("unroll_length=8", algo)


@pytest.mark.parametrize("out_size", [1, 11])
def test_stacked_critics_are_the_two_separate_critics(out_size):
    """The stacked TwinQ's parameters split into q0 and q1 give the separate TwinQ the same outputs, shape included."""
    obs = jax.random.normal(jax.random.PRNGKey(0), (32, 7))
    act = jax.random.uniform(jax.random.PRNGKey(1), (32, 3), minval=-1, maxval=1)
    kw = dict(hidden_sizes=(16, 16), layer_norm=True, out_size=out_size)
    stacked = TwinQ(**kw, stacked=True)
    params = stacked.init(jax.random.PRNGKey(2), obs, act)
    both, separate = stacked.apply(params, obs, act), TwinQ(**kw).apply(unstack_twin_params(params), obs, act)
    assert both.shape == separate.shape
    np.testing.assert_allclose(np.asarray(both), np.asarray(separate), rtol=1e-5, atol=1e-6)
    assert not np.allclose(np.asarray(both[:, 0]), np.asarray(both[:, 1]))  # two critics, not one twice


def test_a_gradient_step_with_stacked_critics_is_the_step_with_separate_ones():
    """From the same parameters and buffer, one SAC gradient step (n-step, categorical critic) of the stacked critics
    ends at the separate critics' parameters, and the actor that learns through them at the same policy."""
    kw = dict(num_envs=8, batch_size=16, max_replay_size=64, min_replay_size=0, n_step=2, distributional=True,
              num_atoms=11, layer_norm=True, q_hidden_sizes=(16, 16), policy_hidden_sizes=(16,))
    stacked, separate = SAC(SACConfig(**kw, stacked_critics=True), 5, 2), SAC(SACConfig(**kw), 5, 2)
    state = stacked.init(jax.random.PRNGKey(0))
    rng = np.random.default_rng(0)
    replay = state.replay
    for _ in range(4):
        f = lambda *shape: jnp.asarray(rng.normal(size=(1, 8) + shape), jnp.float32)
        replay = stacked.insert(replay, Transition(obs=f(5), action=jnp.tanh(f(2)), reward=f(), termination=jnp.zeros((1, 8)),
                                                   truncation=jnp.zeros((1, 8)), next_obs=f(5), extras={}))
    state = state.replace(replay=replay)
    q = unstack_twin_params(state.q_params)
    twin = state.replace(q_params=q, target_q_params=q, q_opt=separate.optimizer.init(q))
    step = lambda sac: jax.jit(lambda s, key: sac.sgd_step(s, key, Parallel(8))[0])  # compiled: faster than op by op
    after_stacked = step(stacked)(state, jax.random.PRNGKey(1))
    after_separate = step(separate)(twin, jax.random.PRNGKey(1))
    moved = jax.tree.leaves(after_separate.q_params)
    for a, b in zip(jax.tree.leaves(unstack_twin_params(after_stacked.q_params)), moved):
        np.testing.assert_allclose(np.asarray(a), np.asarray(b), rtol=1e-4, atol=1e-6)
    assert not all(np.allclose(a, b) for a, b in zip(moved, jax.tree.leaves(q)))  # the critics did step
    for a, b in zip(jax.tree.leaves(after_stacked.policy_params), jax.tree.leaves(after_separate.policy_params)):
        np.testing.assert_allclose(np.asarray(a), np.asarray(b), rtol=1e-4, atol=1e-6)


COLLECTIVE_BYTES = textwrap.dedent("""
    import dataclasses, json, re
    import jax, jax.numpy as jnp
    from agents import driver, presets
    assert jax.local_device_count() == 2
    SIZES = {"f32": 4, "s32": 4, "u32": 4, "bf16": 2, "pred": 1}
    moved = {}
    for batch in (1024, 2048):
        config = presets.make_config("point-mass-sac-fast", devices=2, multi_device="gspmd")
        algo = dataclasses.replace(config.algo, num_envs=256, batch_size=batch, max_replay_size=256 * 40)
        programs = driver.build_programs(config.env_name, config.env, algo, seeds=1, devices=2, updates=10, eval_envs=16,
                                         eval_last_steps=10, learner_cls=None, multi_device="gspmd")
        state = jax.eval_shape(programs.init, jax.ShapeDtypeStruct((1, 2), jnp.uint32))
        state = jax.tree.map(lambda a, s: jax.ShapeDtypeStruct(a.shape, a.dtype, sharding=s), state, programs.shardings)
        text = programs.chunk.lower(state, jax.ShapeDtypeStruct((), jnp.int32)).compile().as_text()
        total = 0
        for line in text.splitlines():
            op = re.search(r" (all-reduce|all-gather|all-to-all|collective-permute|reduce-scatter)(-start)?\\(", line)
            if op:  # the result's shapes, between '=' and the op's name
                for dtype, dims in re.findall(r"(\\w+)\\[([\\d,]*)\\]", line[line.index("=") + 1:op.start()]):
                    n = 1
                    for d in filter(None, dims.split(",")):
                        n *= int(d)
                    total += n * SIZES.get(dtype, 4)
        moved[batch] = total
    print(json.dumps(moved))
""")


def test_two_gspmd_devices_exchange_gradients_not_samples():
    """Fast SAC's chunk on two devices (GSPMD, two CPU devices): the bytes its collectives move are the same at a
    batch of 1,024 and of 2,048, i.e. each device samples its own envs' transitions and learns on them, and only
    gradients and statistics cross devices (a sample that crossed them, or a learner replicated on both, would grow
    with the batch)."""
    env = dict(os.environ, XLA_FLAGS="--xla_force_host_platform_device_count=2",
               PYTHONPATH=os.pathsep.join(p for p in (ROOT, os.environ.get("PYTHONPATH", "")) if p))
    proc = subprocess.run([sys.executable, "-c", COLLECTIVE_BYTES], cwd=ROOT, env=env, capture_output=True, text=True,
                          timeout=HANG_GUARD_S)
    assert proc.returncode == 0, proc.stderr[-3000:]
    moved = json.loads(proc.stdout.strip().splitlines()[-1])
    assert moved["1024"] > 0  # the collectives were found: the comparison is not vacuous
    assert moved["1024"] == moved["2048"], moved


@pytest.mark.parametrize("n_step", [1, 3])
def test_a_batch_smaller_than_the_envs_takes_one_sample_per_block_of_envs(n_step):
    """16 envs, a batch of 4: sample k comes from one of envs 4k .. 4k + 3 (its block), from a written row, and over
    40 draws every env of a block is chosen at some time (the env inside the block is random)."""
    num_envs, steps = 16, 6
    config = SACConfig(num_envs=num_envs, batch_size=4, max_replay_size=8 * num_envs, min_replay_size=0, n_step=n_step)
    sac = SAC(config, 2, 1)
    replay = sac.init(jax.random.PRNGKey(0)).replay
    ids = np.stack(np.meshgrid(np.arange(steps), np.arange(num_envs), indexing="ij"), -1).astype(np.float32)
    zeros = jnp.zeros((1, num_envs))
    for t in range(steps):
        replay = sac.insert(replay, Transition(obs=jnp.asarray(ids[t:t + 1]), action=jnp.zeros((1, num_envs, 1)),
                                               reward=zeros, termination=zeros, truncation=zeros,
                                               next_obs=jnp.asarray(ids[t:t + 1]), extras={}))
    rows, envs = [], []
    sample = jax.jit(lambda r, key: sac.sample(r, key, Parallel(num_envs))[0])
    for k in range(40):
        mb = sample(replay, jax.random.PRNGKey(k))
        rows.append(np.asarray(mb["obs"][:, 0]))
        envs.append(np.asarray(mb["obs"][:, 1]))
    rows, envs = np.stack(rows), np.stack(envs)  # (draws, 4)
    assert np.all(envs // 4 == np.arange(4))
    assert np.all((rows >= 0) & (rows <= steps - n_step))
    assert all(len(set(envs[:, k].tolist())) == 4 for k in range(4))


@pytest.mark.parametrize("batch_size", [64, 4])
def test_each_devices_share_of_an_nstep_sample_is_its_part_of_the_one_device_sample(batch_size):
    """The buffer's env axis split in two halves, each sampled as one device of two sees it (its env ids offset by
    its axis index, as under shard_map): the halves' 3-step samples put together are the one-device sample."""
    num_envs, steps = 8, 7
    config = SACConfig(num_envs=num_envs, batch_size=batch_size, max_replay_size=6 * num_envs, min_replay_size=0,
                       n_step=3)
    sac = SAC(config, 2, 1)
    replay = sac.init(jax.random.PRNGKey(0)).replay
    rng = np.random.default_rng(3)
    for _ in range(steps):  # wraps around the 6 rows
        f = lambda *shape: jnp.asarray(rng.normal(size=(1, num_envs) + shape).astype(np.float32))  # noqa: E731
        flag = lambda: jnp.asarray((rng.random((1, num_envs)) < 0.2).astype(np.float32))  # noqa: E731
        replay = sac.insert(replay, Transition(obs=f(2), action=f(1), reward=f(), termination=flag(), truncation=flag(),
                                               next_obs=f(2), extras={}))
    key = jax.random.PRNGKey(5)
    whole, _ = jax.jit(lambda r: sac.sample(r, key, Parallel(num_envs)))(replay)
    halves = replay.replace(data=jax.tree.map(lambda x: jnp.stack(jnp.split(x, 2, axis=1)), replay.data))
    shares, _ = jax.jit(jax.vmap(lambda r: sac.sample(r, key, Parallel(num_envs, 2, "dev")),
                                 in_axes=(Replay(0, None, None),), axis_name="dev"))(halves)
    for name in whole:
        np.testing.assert_array_equal(np.concatenate(np.asarray(shares[name])), np.asarray(whole[name]), err_msg=name)
