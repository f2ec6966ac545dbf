"""Policy exports: written by the driver (point-mass PPO, compiles in seconds) and by SAC, read back by eval.py and
tools/ship_checkpoint.py, acting as the learner they came from.
"""

import dataclasses
import json
import shutil

import jax
import jax.numpy as jnp
import numpy as np
import pytest

import envs
import eval as eval_cli
from agents import evaluation, export, presets, registry
from agents.config import config_json
from agents.eval_stats import overruled_share
from agents.loop import make_evaluate, make_evaluate_stacked
from tools import ship_checkpoint
from tools.ship_checkpoint import best_seed


def test_driver_writes_policy_exports_that_reproduce_its_evaluation(point_run):
    for step in (5120, 10240):
        directory = point_run / "checkpoints" / str(step) / "policy"
        assert (directory / "policy.json").is_file()
        assert (directory / "policy.npz").is_file()
        assert sum(f.stat().st_size for f in directory.iterdir()) < 200_000  # params + statistics only
    policy = evaluation.checkpoint_policy(str(point_run))  # a logdir: its newest checkpoint
    assert policy.export.env_steps == 10240
    assert policy.units == [0, 1]
    assert policy.train_env_name == "point-mass"
    # The export acts exactly as the trained learner: same numbers as the driver's eval.json.
    result = evaluation.run(policy, "point-mass", policy.train_env_config, num_envs=64)
    ev = json.loads((point_run / "eval.json").read_text())
    for name, key in (("target_reached", "episode/target_reached"), ("distance", "episode/distance_last10"),
                      ("return", "episode/return")):
        np.testing.assert_allclose([u["metrics"][name] for u in result.units], ev["per_seed"][key], rtol=1e-5, atol=1e-6)
    assert 0 < result.summary()["target_reached"]["mean"] <= 1
    # A step directory names that checkpoint.
    older = evaluation.checkpoint_policy(str(point_run / "checkpoints" / "5120"))
    assert older.export.env_steps == 5120
    assert not np.allclose(older.export.state.params["policy"]["params"]["out"]["kernel"],
                           policy.export.state.params["policy"]["params"]["out"]["kernel"])


def test_a_memory_metric_is_reported_at_the_episodes_last_step():
    """A memory counting the executed steps, read by `memory_metrics`, ends each episode at the episode's length."""
    env = envs.wrap(envs.make("point-mass", episode_length=20), autoreset=False)
    act = lambda ls, state, start, k, count: (jnp.ones((state.obs.shape[0], env.action_size)), count + 1.0)
    evaluate = make_evaluate(env, None, 8, 20, act=act, per_env=True, memory=lambda start: jnp.zeros(8),
                             memory_metrics=lambda count: {"executed": count})
    out = jax.jit(evaluate)(None, jax.random.PRNGKey(0))
    np.testing.assert_array_equal(out["episode/executed"], out["episode/length"])


def test_memory_metrics_without_a_memory_are_refused():
    with pytest.raises(ValueError, match="memory_metrics without unit_act is invalid"):
        make_evaluate_stacked(None, None, 8, 20, memory_metrics=lambda mem: {})


def test_the_overruled_share_pools_the_units_steps():
    units = [{"metrics": {"overruled_steps": 2.0, "episode_length": 10.0}},
             {"metrics": {"overruled_steps": 4.0, "episode_length": 30.0}}]
    assert overruled_share(units) == pytest.approx(0.15)


def test_trained_seeds_side_by_side_act_as_each_seed_alone(point_run):
    """`make_evaluate_stacked` steps the trained seeds' envs as one batch: each seed's episode returns and observed
    trajectories equal that seed's own evaluation (`make_evaluate` on its state alone), on the same episodes."""
    policy = evaluation.checkpoint_policy(str(point_run))
    learner, states, config = policy.export.learner, policy.export.state, policy.train_env_config
    env = envs.wrap(envs.from_config("point-mass", config), autoreset=False)
    observe = lambda state: {"obs": state.obs}
    key = jax.random.PRNGKey(3)
    out, records = jax.jit(make_evaluate_stacked(env, learner, 16, config.episode_length, per_env=True,
                                                 record=observe))(states, key)
    assert out["episode/return"].shape == (2, 16)
    assert records["obs"].shape[:3] == (2, config.episode_length + 1, 16)
    assert not np.allclose(out["episode/return"][0], out["episode/return"][1])  # two different policies
    alone = jax.jit(make_evaluate(env, learner, 16, config.episode_length, per_env=True, record=observe))
    for unit in range(2):
        own, own_records = alone(jax.tree.map(lambda x: x[unit], states), key)
        np.testing.assert_allclose(out["episode/return"][unit], own["episode/return"], rtol=1e-5, atol=1e-6)
        np.testing.assert_allclose(records["obs"][unit], own_records["obs"], rtol=1e-5, atol=1e-6)


def test_checkpoint_without_export_gets_one_from_the_full_state(point_run, tmp_path):
    run = tmp_path / "old"
    shutil.copytree(point_run, run)
    shutil.rmtree(run / "checkpoints" / "10240" / "policy")  # as written before exports existed
    policy = evaluation.checkpoint_policy(str(run))
    assert (run / "checkpoints" / "10240" / "policy" / "policy.json").is_file()
    fresh = evaluation.checkpoint_policy(str(point_run))
    for a, b in zip(jax.tree.leaves(policy.export.state), jax.tree.leaves(fresh.export.state)):
        np.testing.assert_array_equal(a, b)


def test_export_of_one_seed_acts_as_that_seed_of_the_run(point_run, tmp_path):
    full = evaluation.checkpoint_policy(str(point_run))
    r_full = evaluation.run(full, "point-mass", full.train_env_config, num_envs=32)
    (tmp_path / "eval.json").write_text(json.dumps({"evaluations": [r_full.to_json()]}, default=evaluation.jsonable))
    reached = [u["metrics"]["target_reached"] for u in r_full.units]
    assert reached[0] != reached[1]
    best = int(np.argmax(reached))
    out = ship_checkpoint.main([str(point_run), str(tmp_path / "best"), "--best-from", str(tmp_path / "eval.json")])
    one = evaluation.checkpoint_policy(out)
    assert one.units == [best]
    assert one.export.env_steps == 10240
    assert json.loads((tmp_path / "best" / "policy.json").read_text())["selected_from"]["seeds"] == [0, 1]
    for a, b in zip(jax.tree.leaves(one.export.state), jax.tree.leaves(full.export.state)):
        np.testing.assert_array_equal(a[0], b[best])
    r_one = evaluation.run(one, "point-mass", one.train_env_config, num_envs=32)
    assert r_one.units[0]["metrics"] == r_full.units[best]["metrics"]
    with pytest.raises(ValueError, match=r"seeds=\[2\] is invalid .* allowed are distinct seeds out of \[0, 1\]"):
        export.select(str(point_run), str(tmp_path / "bad"), [2])
    with pytest.raises(ValueError, match="no evaluation of the checkpoint at 5120 env steps"):
        ship_checkpoint.main([str(point_run / "checkpoints" / "5120"), str(tmp_path / "old"), "--best-from",
                              str(tmp_path / "eval.json")])
    # The run's own eval.json (the training driver's, per seed): its best seed, by hand from its lists.
    own = json.loads((point_run / "eval.json").read_text())["per_seed"]
    reached = own["episode/target_reached"]  # the point mass reports no collisions
    assert "episode/self_collision" not in own
    assert reached[0] != reached[1]
    scores = list(reached)
    out = ship_checkpoint.main([str(point_run), str(tmp_path / "best_own"), "--best-from",
                                str(point_run / "eval.json")])
    assert evaluation.checkpoint_policy(out).units == [scores.index(max(scores))]
    with pytest.raises(ValueError, match=r"it evaluates 10240 env steps, the checkpoint has 5120"):
        ship_checkpoint.main([str(point_run / "checkpoints" / "5120"), str(tmp_path / "old"), "--best-from",
                              str(point_run / "eval.json")])


def test_best_seed_of_a_runs_own_eval_json(tmp_path):
    """The driver's eval.json lists one value per seed in the export's seed order: seeds 5-7, two tied on target
    reached, the one with fewer collisions wins; lists of another length or another checkpoint are refused."""
    path = tmp_path / "eval.json"
    path.write_text(json.dumps({"env_steps": 100, "per_seed": {
        "episode/target_reached": [0.9, 0.95, 0.95], "episode/self_collision": [0.0, 0.03, 0.01],
        "episode/obstacle_collision": [0.0, 0.0, 0.01]}}))
    assert best_seed(str(path), 100, [5, 6, 7]) == 7  # 0.02 collisions against seed 6's 0.03
    with pytest.raises(ValueError, match=r"do not hold one value for each of the export's seeds \[5, 6\]"):
        best_seed(str(path), 100, [5, 6])
    with pytest.raises(ValueError, match="it evaluates 100 env steps, the checkpoint has 200"):
        best_seed(str(path), 200, [5, 6, 7])


def test_stochastic_evaluation_samples_the_policy(point_run):
    """`eval.py --stochastic`: the actions are tanh(mean + std * noise) of the policy's distribution
    (mean and std by hand from the network's output), not the mode tanh(mean); the episodes are
    reproducible for one key and differ from the deterministic ones."""
    policy = evaluation.checkpoint_policy(str(point_run))
    learner, state = policy.export.learner, jax.tree.map(lambda x: x[0], policy.export.state)
    obs = jax.random.normal(jax.random.PRNGKey(1), (5, policy.export.observation_size))
    key = jax.random.PRNGKey(2)
    out = np.asarray(learner.policy_net.apply(state.params["policy"], learner._obs(state, obs)), np.float64)
    mean, raw = np.split(out, 2, axis=-1)
    std = np.log1p(np.exp(raw)) + learner.config.min_std  # softplus
    noise = np.asarray(jax.random.normal(key, mean.shape))
    np.testing.assert_allclose(learner.stochastic_policy(state, obs, key), np.tanh(mean + std * noise), rtol=1e-5, atol=1e-6)
    np.testing.assert_allclose(learner.policy(state, obs), np.tanh(mean), rtol=1e-5, atol=1e-6)
    config = policy.train_env_config
    det = evaluation.run(policy, "point-mass", config, num_envs=32)
    sto = evaluation.run(policy, "point-mass", config, num_envs=32, stochastic=True)
    again = evaluation.run(policy, "point-mass", config, num_envs=32, stochastic=True)
    assert sto.units == again.units
    assert sto.units != det.units
    assert sto.to_json()["actions"] == "stochastic"
    assert det.to_json()["actions"] == "deterministic"
    assert evaluation.markdown([sto]).count(", stochastic)") == 1
    # A video's rollout shows the evaluated episodes: sampled actions with --stochastic, the mode without.
    for result, stochastic in ((sto, True), (det, False)):
        records = evaluation.rollout(policy, "point-mass", config, num_envs=32, stochastic=stochastic)
        np.testing.assert_allclose(records["metrics"]["episode/return"], result.per_env["return"][0], rtol=1e-5, atol=1e-6)
    with pytest.raises(ValueError, match="stochastic=True is invalid for the baseline 'random'"):
        evaluation.run(evaluation.baseline_policy("random"), "point-mass", config, num_envs=4, stochastic=True)


def test_several_checkpoints_pooled(point_run, capsys):
    step = str(point_run / "checkpoints" / "5120")
    results = eval_cli.main(["--checkpoint", str(point_run), step, "--num-envs", "16", "--seeds", "2"])
    assert [len(r.units) for r in results] == [4, 4]  # 2 trained seeds x 2 eval seeds each
    out = capsys.readouterr().out
    assert "all checkpoints | point-mass | 8 x 16" in out
    pooled = evaluation.pooled(results)
    assert pooled["target_reached"]["units"] == 8


def _sac_point_mass(seeds: int = 2):
    """(config, env, learner, freshly initialised state with `seeds` seeds) of a small point-mass SAC."""
    config = presets.make_config("point-mass-sac", seeds=seeds)
    config = dataclasses.replace(config, algo=dataclasses.replace(config.algo, max_replay_size=1024,
                                                                                min_replay_size=256))
    env = envs.make("point-mass")
    learner = registry.make_learner(config.algo, env.observation_size, env.action_size, 1)
    state = jax.jit(jax.vmap(learner.init))(jax.random.split(jax.random.PRNGKey(0), seeds))
    return config, env, learner, state


def test_sac_export_acts_as_the_learner(tmp_path):
    """A SAC state's export (policy params + observation statistics) gives the learner's actions."""
    config, env, learner, state = _sac_point_mass()
    stats = state.obs_stats.replace(mean=state.obs_stats.mean + 0.3, var=state.obs_stats.var * 2.0)  # non-trivial
    state = state.replace(obs_stats=stats)
    export.save(str(tmp_path / "policy"), learner, state, config_json(config), 640)
    loaded = export.load(str(tmp_path))
    assert loaded.config.algo_name == "sac"
    assert loaded.seeds == [0, 1]
    assert loaded.env_steps == 640
    assert sum(f.stat().st_size for f in (tmp_path / "policy").iterdir()) < 100_000  # no replay buffer
    obs = jax.random.normal(jax.random.PRNGKey(1), (5, env.observation_size))
    ours = jax.vmap(loaded.learner.policy, in_axes=(0, None))(loaded.state, obs)
    theirs = jax.vmap(learner.policy, in_axes=(0, None))(state, obs)
    np.testing.assert_allclose(ours, theirs, rtol=1e-6)
    assert not np.allclose(ours[0], ours[1])  # the seeds differ
    key = jax.random.PRNGKey(3)  # sampled actions: tanh(mean + std * noise) of seed 0's distribution
    first = jax.tree.map(lambda x: x[0], loaded.state)
    dist = learner._dist(first.policy_params, learner._obs(first.obs_stats, obs))
    expected = np.tanh(np.asarray(dist.mean) + np.asarray(dist.std) * np.asarray(jax.random.normal(key, dist.mean.shape)))
    np.testing.assert_allclose(loaded.learner.stochastic_policy(first, obs, key), expected, rtol=1e-5, atol=1e-6)



def test_sac_export_evaluated_in_bfloat16(tmp_path):
    """eval.py --compute-dtype: the evaluation acts with the chosen number format (its own program)."""
    config, env, learner, state = _sac_point_mass()
    export.save(str(tmp_path / "policy"), learner, state, config_json(config), 640)
    loaded = export.load(str(tmp_path))
    obs = jax.random.normal(jax.random.PRNGKey(1), (5, env.observation_size))
    ours = np.asarray(jax.vmap(loaded.learner.policy, in_axes=(0, None))(loaded.state, obs))
    policy = evaluation.Policy("checkpoint", str(tmp_path), loaded.seeds, loaded)
    with pytest.raises(ValueError, match=r"compute_dtype='float16' is invalid: allowed are 'float32', 'bfloat16'"):
        evaluation.with_compute_dtype(policy, "float16")
    bf16 = evaluation.with_compute_dtype(policy, "bfloat16")
    assert policy.algo_config.compute_dtype == "float32"
    assert bf16.algo_config.compute_dtype == "bfloat16"
    bf16_learner = registry.make_learner(bf16.algo_config, env.observation_size, env.action_size, 1)
    acted = np.asarray(jax.vmap(bf16_learner.policy, in_axes=(0, None))(loaded.state, obs))
    assert not np.array_equal(acted, ours)  # close to float32's actions, not equal
    np.testing.assert_allclose(acted, ours, atol=0.05)
    # The evaluation compiles its own program for the bfloat16 learner; the label and the JSON say which.
    cfg = loaded.config.env
    assert evaluation._program(bf16, "point-mass", cfg, 4, 10, False) is not evaluation._program(policy, "point-mass", cfg, 4, 10, False)
    assert evaluation._program(evaluation.with_compute_dtype(policy, "float32"), "point-mass", cfg, 4, 10, False) is \
        evaluation._program(policy, "point-mass", cfg, 4, 10, False)
    result = evaluation.run(bf16, "point-mass", cfg, num_envs=4, eval_seeds=(5,))
    assert result.to_json()["policy"]["compute_dtype"] == "bfloat16"
    assert "compute_dtype" not in policy.describe()
    assert evaluation.label(result).endswith(", bfloat16)")
