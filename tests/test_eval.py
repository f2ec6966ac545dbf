"""eval.py and its library (agents.evaluation, agents.export, agents.baselines): metric aggregation
on hand-built episodes, the paper's baselines, policy exports written by the driver, evaluation of a
checkpoint on another workspace, bad input, rendering.

CPU cost is dominated by compiling MJX rollouts (~25 s each on 2 cores), so every compiled
evaluation is shared: module-scoped fixtures, and eval.py subprocesses run the same programs as the
in-process tests with the persistent compilation cache (`.jax_cache/`, see conftest.py) switched on.
"""

import dataclasses
import datetime
import json
import os
import shlex
import shutil
import subprocess
import sys

import jax
import jax.numpy as jnp
import numpy as np
import pytest

import envs
import eval as eval_cli
from agents import baselines, driver, evaluation, export, presets, registry
from agents.config import config_json
from agents.eval_stats import overruled_share
from agents.loop import episode_metrics, make_evaluate, make_evaluate_stacked
from mujoco_reference import colliding_configuration, colliding_pairs, contact_model, ee_position
from limits import HANG_GUARD_S

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
QUIET = dict(tensorboard=False, progress=False)


def _subprocess_env():
    path = os.pathsep.join(p for p in (ROOT, os.environ.get("PYTHONPATH", "")) if p)
    return dict(os.environ, PYTHONPATH=path, JAX_COMPILATION_CACHE_DIR=jax.config.jax_compilation_cache_dir,
                JAX_PERSISTENT_CACHE_MIN_COMPILE_TIME_SECS="1")


def _eval_cli(*args, timeout=HANG_GUARD_S):
    return subprocess.run([sys.executable, "eval.py", *args], cwd=ROOT, env=_subprocess_env(), capture_output=True,
                          text=True, timeout=timeout)


# ------------------------------------------------------------------------------------------------
# Aggregation


def test_episode_metrics_on_a_hand_built_rollout():
    """Env 0: reach (t=1), leave (t=2), re-enter (t=3), collide (t=4, done), then a later episode that
    must be ignored. Env 1: never done; its episode is the whole rollout."""
    T = 14
    done = np.zeros((T, 2), np.float32)
    done[4, 0] = 1.0
    done[9, 0] = 1.0  # second episode of env 0: ignored
    reward = np.ones((T, 2), np.float32)
    reward[4, 0] = 0.0  # the collision step
    distance = np.tile(np.linspace(1.0, 0.1, T, dtype=np.float32)[:, None], (1, 2))
    distance[:5, 0] = [0.05, 0.005, 0.1, 0.004, 0.3]
    metrics = {
        "distance": distance,
        "target_reached": np.zeros((T, 2), np.float32),
        "steps_in_target": np.zeros((T, 2), np.float32),
        "times_left_target": np.zeros((T, 2), np.float32),
        "self_collision": np.zeros((T, 2), np.float32),
    }
    metrics["target_reached"][:4, 0] = [0, 1, 1, 1]
    metrics["target_reached"][4, 0] = 0  # a collision voids the reach
    metrics["steps_in_target"][:5, 0] = [0, 1, 1, 2, 2]
    metrics["times_left_target"][:5, 0] = [0, 0, 1, 1, 1]
    metrics["self_collision"][4, 0] = 1
    metrics["self_collision"][5:, 0] = 7.0  # garbage of later episodes
    out = jax.device_get(episode_metrics(jnp.asarray(done), jnp.asarray(reward),
                                         {k: jnp.asarray(v) for k, v in metrics.items()}, last_steps=3))
    np.testing.assert_allclose(out["episode/length"], [5, T])
    np.testing.assert_allclose(out["episode/return"], [4, T])
    np.testing.assert_allclose(out["episode/self_collision"], [1, 0])
    np.testing.assert_allclose(out["episode/target_reached"], [0, 0])
    np.testing.assert_allclose(out["episode/steps_in_target"], [2, 0])
    np.testing.assert_allclose(out["episode/times_left_target"], [1, 0])
    np.testing.assert_allclose(out["episode/distance"], [0.3, distance[-1, 1]])
    np.testing.assert_allclose(out["episode/distance_last3"], [(0.1 + 0.004 + 0.3) / 3, distance[-3:, 1].mean()], rtol=1e-6)
    # Summaries: mean and std over units and over episodes.
    s = evaluation.summarize({"x": np.array([[1.0, 0.0, 0.0, 1.0], [1.0, 1.0, 1.0, 1.0]])})["x"]
    assert s["mean"] == 0.75
    assert s["std_units"] == 0.25
    assert np.isclose(s["std_episodes"], np.sqrt(3) / 4)


def _with_target(state, target):
    return state.replace(info={**state.info, "target_pos": jnp.asarray(target, jnp.float32)})


def test_episode_metrics_on_env_states():
    """The reach / leave / re-enter / collide sequence of tests/test_envs.py built from real env
    states (same compiled step, shared through the compilation cache), then aggregated."""
    n = 4  # tests/test_envs.py's batch: the compiled step comes from the cache
    env = envs.wrap(envs.make("ur5e-reach"))
    step = jax.jit(env.step)
    still = jnp.zeros((n, 6))
    ee = lambda s: np.asarray(step(s, still).pipeline_state.site_xpos)[:, env.unwrapped.robot.ee_site]
    states = [jax.jit(env.reset)(jax.random.split(jax.random.PRNGKey(14), n))]
    offsets = [0.0, 0.1, 0.0]  # in target, 10 cm off, back in
    for off in offsets:
        s = states[-1]
        states.append(step(_with_target(s, ee(s) + np.array([off, 0, 0])), still))
    # Step 4: a colliding configuration; step 5: the next episode (auto-reset) goes on.
    q = colliding_configuration(env.unwrapped.robot, seed=15)
    s = states[-1]
    data = s.pipeline_state.replace(qpos=jnp.tile(q, (n, 1)), qvel=jnp.zeros_like(s.pipeline_state.qvel))
    states.append(step(s.replace(pipeline_state=data), still))
    states.append(step(states[-1], still))
    seq = states[1:]
    done = jnp.stack([s.done for s in seq])
    reward = jnp.stack([s.reward for s in seq])
    metrics = {k: jnp.stack([s.metrics[k] for s in seq]) for k in seq[0].metrics}
    out = jax.device_get(episode_metrics(done, reward, metrics, last_steps=10))
    np.testing.assert_array_equal(out["episode/length"], 4)
    np.testing.assert_array_equal(out["episode/self_collision"], 1)
    np.testing.assert_array_equal(out["episode/target_reached"], 0)
    np.testing.assert_array_equal(out["episode/steps_in_target"], 2)
    np.testing.assert_array_equal(out["episode/times_left_target"], 1)
    d = np.stack([np.asarray(s.metrics["distance"]) for s in seq[:4]])
    np.testing.assert_allclose(out["episode/distance_last10"], d.mean(0), rtol=1e-5)
    np.testing.assert_allclose(out["episode/return"], np.asarray(reward)[:4].sum(0), rtol=1e-6)


# ------------------------------------------------------------------------------------------------
# Policy exports written by the driver (point mass: compiles in seconds)


@pytest.fixture(scope="module")
def point_run(tmp_path_factory):
    """A 2-seed point-mass PPO run with checkpoints at 5120 and 10240 env steps."""
    logdir = tmp_path_factory.mktemp("point") / "run"
    config = presets.make_config("point-mass-ppo", num_timesteps=10240, checkpoint_every=5120, seeds=2,
                                   eval_envs=64, logdir=str(logdir), **QUIET)
    driver.train(config)
    return logdir


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
    from tools import ship_checkpoint

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
    from tools.ship_checkpoint import best_seed

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


# ------------------------------------------------------------------------------------------------
# Baselines (one compiled evaluation serves all three: the baseline is a traced index)

BASELINE_ENV = dict(action="absolute", episode_length=100, target_radius=0.02)
"""Absolute control (the paper's baselines, see eval.py) and 100 steps (4 s): the random agent's
collisions come early (median step 20 at 4096 envs), the pseudo-IK needs ~80 steps on average to
swing its joints (up to 4 pi rad at ~pi rad/s) to the target's pose."""


BASELINE_ARGS = ["--env", "ur5e-reach", "--num-envs", "16"] + [f"--env.{k.replace('_', '-')}={v}" for k, v in BASELINE_ENV.items()]


@pytest.fixture(scope="module")
def baseline_runs(tmp_path_factory):
    """eval.py (in process) for each baseline: {name: (result, json path, csv path)}."""
    out = tmp_path_factory.mktemp("baselines")
    runs = {}
    for name in baselines.BASELINES:
        paths = (out / f"{name}.json", out / f"{name}.csv")
        [result] = eval_cli.main(BASELINE_ARGS + ["--policy", name, "--json", str(paths[0]), "--csv", str(paths[1])])
        runs[name] = (result, *paths)
    return runs


@pytest.fixture(scope="module")
def baseline_results(baseline_runs):
    return {name: run[0] for name, run in baseline_runs.items()}


def test_baselines_behave_as_in_the_paper(baseline_results):
    s = {name: r.summary() for name, r in baseline_results.items()}
    # Standstill: holds its initial pose, never reaches, never collides.
    assert s["standstill"]["target_reached"]["mean"] == 0
    assert s["standstill"]["self_collision"]["mean"] == 0
    assert s["standstill"]["steps_in_target"]["mean"] == 0
    # Random (absolute control): flails and self-collides often (paper 30 %, ours 22 % at 4096 envs).
    assert s["random"]["target_reached"]["mean"] == 0
    assert s["random"]["self_collision"]["mean"] >= 2 / 16
    # Pseudo-IK: commands the target's own pose; a fair share reaches, the rest collides on the way
    # or settles off target under gravity; far closer than standing still.
    assert s["pseudo_ik"]["target_reached"]["mean"] >= 3 / 16
    assert s["pseudo_ik"]["distance_not_collided"]["mean"] < 0.5 * s["standstill"]["distance"]["mean"]
    assert s["pseudo_ik"]["steps_in_target"]["mean"] > 0
    # Same episodes for every baseline (one evaluation seed): same initial distances.
    assert baseline_results["random"].eval_seeds == baseline_results["standstill"].eval_seeds


def test_derived_precision_metrics_by_hand():
    """Per-episode readings of the final distance, on hand-made episodes: 2 units x 3 episodes."""
    per_env = {"distance": np.array([[0.004, 0.30, 0.006], [0.002, 0.008, 0.50]]),
               "steps_in_target": np.array([[90.0, 0.0, 70.0], [100.0, 60.0, 0.0]]),
               "target_reached": np.array([[1.0, 0.0, 1.0], [1.0, 1.0, 0.0]]),
               "self_collision": np.array([[0.0, 1.0, 0.0], [0.0, 0.0, 0.0]])}
    derived = {**evaluation.collided_distances(per_env), **evaluation.reached_precision(per_env)}
    s = evaluation.summarize({**per_env, **derived})
    assert s["distance"]["mean"] == pytest.approx(((0.004 + 0.30 + 0.006) / 3 + (0.002 + 0.008 + 0.50) / 3) / 2)
    assert s["distance_reached"]["mean"] == pytest.approx((0.005 + 0.005) / 2)  # unit means over reached episodes
    assert s["distance_reached"]["episodes"] == 4
    assert s["steps_in_target_reached"]["mean"] == pytest.approx((80.0 + 80.0) / 2)
    assert s["distance_not_collided"]["mean"] == pytest.approx((0.005 + (0.002 + 0.008 + 0.50) / 3) / 2)
    assert s["distance_collided_as_0"]["mean"] == pytest.approx((0.010 / 3 + 0.510 / 3) / 2)


def test_baseline_actions_command_the_right_joint_targets():
    """standstill / pseudo-IK actions invert the env's action mapping in both modes."""
    for action in ("absolute", "relative"):
        env = envs.wrap(envs.make("ur5e-reach", action=action))
        base = env.unwrapped
        robot = base.robot
        rng = np.random.default_rng(0)
        q = rng.uniform(robot.joint_low, robot.joint_high, (5, 6)).astype(np.float32)
        near = np.clip(q + rng.uniform(-0.05, 0.05, q.shape), robot.joint_low, robot.joint_high).astype(np.float32)
        a = baselines.joint_target_action(base.config, robot, jnp.asarray(near), jnp.asarray(q))
        np.testing.assert_allclose(base.action_to_ctrl(a, jnp.asarray(q)), near, atol=2e-5)
        far = q + 1.0  # relative control: one step of at most action_scale towards it
        a = baselines.joint_target_action(base.config, robot, jnp.asarray(far), jnp.asarray(q))
        if action == "relative":
            np.testing.assert_allclose(a, 1.0)


def test_pseudo_ik_with_relative_to_target_commands_the_target_pose():
    """relative_to="target": pseudo-IK's deltas are taken from the last targets, so its commanded targets
    reach the target pose exactly after ceil(max |target - start| / action_scale) steps and stay there."""
    env = envs.wrap(envs.make("ur5e-reach", backend="mujoco", relative_to="target", action_scale=0.5), autoreset=False)
    act, step = jax.jit(baselines.make_act(env)), jax.jit(env.step)
    start = state = jax.jit(env.reset)(jax.random.split(jax.random.PRNGKey(2), 2))  # jitted: one step program
    needed = int(np.ceil(np.abs(np.asarray(start.info["target_qpos"] - start.pipeline_state.qpos)).max() / 0.5))
    for t in range(needed + 1):
        before = state.pipeline_state.ctrl
        state = step(state, act(baselines.index("pseudo_ik"), state, start, jax.random.PRNGKey(t)))
        if t == needed - 1:
            assert np.abs(np.asarray(before - start.info["target_qpos"])).max() > 1e-4  # not there a step early
    np.testing.assert_allclose(state.pipeline_state.ctrl, start.info["target_qpos"], atol=1e-5)


def test_cli_baseline_json_csv(baseline_runs):
    """The contract `eval.py --env ur5e-reach --policy standstill --num-envs N --json out.json`."""
    result, out, table = baseline_runs["standstill"]
    report = json.loads(out.read_text())
    ev = report["evaluations"][0]
    assert report["env_name"] == "ur5e-reach"
    assert report["num_envs"] == 16
    assert report["eval_seeds"] == [1_000_000]
    assert report["command"].startswith("python eval.py --env ur5e-reach --num-envs 16")
    assert report["date"] == datetime.date.today().isoformat()  # with command, code, device: agents/provenance.py
    assert ev["policy"] == {"kind": "baseline", "name": "standstill"}
    assert ev["env_config"]["action"] == "absolute"
    assert ev["env_config"]["episode_length"] == 100
    assert ev["env_config"]["substeps"] == 20  # untouched fields: the env's defaults
    assert set(ev["summary"]) >= {"target_reached", "self_collision", "obstacle_collision", "distance",
                                  "steps_in_target", "times_left_target"}
    assert ev["summary"]["distance"]["mean"] == pytest.approx(result.summary()["distance"]["mean"])
    assert len(ev["units"]) == 1
    assert ev["units"][0]["metrics"]["target_reached"] == 0
    wall = report["wall_seconds"]  # where the process's time went
    assert wall["evaluations"] == pytest.approx(ev["seconds"], abs=0.01)
    assert wall["before_evaluations"] + wall["evaluations"] <= wall["total"] + 0.01
    rows = table.read_text().splitlines()
    assert len(rows) == 2
    assert "target_reached" in rows[0]
    assert rows[1].startswith("standstill,ur5e-reach,")


# ------------------------------------------------------------------------------------------------
# A checkpoint on another workspace (an untrained UR5e policy written as the driver writes exports:
# evaluation only needs its shapes and config; training it would compile PPO for a minute)

ARM_ENV = dict(substeps=2, episode_length=20)


def _untrained_export(directory, env_name="ur5e-reach", **env_options):
    """A policy export as the driver writes it, of an untrained PPO policy (no compilation)."""
    config = presets.make_config("ur5e-reach-ppo-cpu", env_name=env_name, env=envs.make_config(env_name, **env_options))
    env = envs.make(env_name, **env_options)
    learner = registry.make_learner(config.algo, env.observation_size, env.action_size, 1)
    state = jax.vmap(learner.init)(jax.random.split(jax.random.PRNGKey(0), 1))
    step_dir = directory / "run" / "checkpoints" / "1280"
    export.save(str(step_dir / "policy"), learner, state, config_json(config), 1280)
    return step_dir.parent.parent  # the logdir


@pytest.fixture(scope="module")
def arm_export(tmp_path_factory):
    return _untrained_export(tmp_path_factory.mktemp("arm"), **ARM_ENV)


def test_checkpoint_evaluated_on_another_workspace(arm_export):
    policy = evaluation.checkpoint_policy(str(arm_export))
    assert policy.train_env_config.workspace == "full"
    config = envs.make_config("ur5e-reach", policy.train_env_config, workspace="front")
    assert config.substeps == 2
    assert config.episode_length == 20  # the checkpoint's, not the defaults
    result = evaluation.run(policy, "ur5e-reach", config, num_envs=4)
    report = result.to_json()
    assert report["env_config"]["workspace"] == "front"
    assert report["policy"]["train_env_name"] == "ur5e-reach"
    assert report["policy"]["train_config"]["env"]["workspace"] == "full"
    s = result.summary()
    assert 0 <= s["self_collision"]["mean"] <= 1
    assert 0 < s["distance"]["mean"] < 2.5
    assert s["distance"]["units"] == 1
    assert s["distance"]["episodes"] == 4


@pytest.fixture(scope="module")
def arm_rollout(arm_export):
    policy = evaluation.checkpoint_policy(str(arm_export))
    config = envs.make_config("ur5e-reach", policy.train_env_config, workspace="front")
    return policy, config, evaluation.rollout(policy, "ur5e-reach", config, num_envs=4)


def test_rollout_shows_the_evaluated_episodes(arm_rollout):
    policy, config, records = arm_rollout
    assert records["qpos"].shape == (config.episode_length + 1, 4, 6)
    assert (records["target_pos"][0, :, 0] >= 0).all()  # front workspace: x >= 0
    assert np.abs(records["qpos"][-1] - records["qpos"][0]).max() > 1e-3  # the policy moved the arm
    # Same episodes as the evaluation with as many envs (same compiled program as the test above).
    result = evaluation.run(policy, "ur5e-reach", config, num_envs=4)
    for name in ("distance", "self_collision", "episode_length"):
        key = evaluation.PAPER_METRICS.get(name) or evaluation.EXTRA_METRICS[name]
        np.testing.assert_allclose(records["metrics"][key], result.per_env[name][0], rtol=1e-5, atol=1e-6)


def test_env_without_autoreset_stays_in_its_first_episode():
    """`envs.wrap(env, autoreset=False)`, the evaluation's env: for one key the initial states of the
    training stack, and no fresh episode once the first ends (point mass, 3-step episodes, standing still)."""
    env = envs.make("point-mass", episode_length=3)
    keys = jax.random.split(jax.random.PRNGKey(0), 4)
    once, auto = envs.wrap(env, autoreset=False), envs.wrap(env)
    first, fresh = once.reset(keys), auto.reset(keys)
    np.testing.assert_array_equal(first.obs, fresh.obs)
    still = jnp.zeros((4, env.action_size))
    for _ in range(4):
        first, fresh = once.step(first, still), auto.step(fresh, still)
    np.testing.assert_array_equal(first.info["steps"], 4)  # still the first episode, ended at step 3
    np.testing.assert_array_equal(first.done, 1)
    np.testing.assert_array_equal(fresh.info["steps"], 1)  # the next episode's first step


def test_first_restarts_repeat_each_envs_first_episode_and_fresh_ones_do_not():
    """`restarts="first"` (Brax's auto-reset, `TrainConfig.episode_restarts`): after an episode ends each env starts
    again from exactly its first initial state; the default samples a new one (point mass, 3-step episodes)."""
    env = envs.make("point-mass", episode_length=3)
    keys = jax.random.split(jax.random.PRNGKey(0), 4)
    first_env, fresh_env = envs.wrap(env, restarts="first"), envs.wrap(env)
    first, fresh = first_env.reset(keys), fresh_env.reset(keys)
    start = first.obs
    np.testing.assert_array_equal(start, fresh.obs)  # the same first episodes
    still = jnp.zeros((4, env.action_size))
    for episode in range(2):
        for _ in range(3):
            first, fresh = first_env.step(first, still), fresh_env.step(fresh, still)
        np.testing.assert_array_equal(first.info["steps"], 0)  # a new episode has started...
        np.testing.assert_array_equal(first.obs, start)  # ...from the env's first initial state, every time
        assert not np.allclose(fresh.obs, start), episode  # the default samples anew


def test_unknown_restarts_are_refused_naming_the_allowed():
    with pytest.raises(ValueError, match=r"restarts='brax' is unknown: allowed are fresh, first"):
        envs.wrap(envs.make("point-mass"), restarts="brax")


def test_registry_names_each_envs_robot():
    """What eval.py asks to refuse a checkpoint on another robot and a video of an env without one."""
    robots = {name: envs.registry.spec(name).robot for name in envs.names()}
    assert robots == {"panda-reach": "panda", "panda-reach-avoid": "panda", "point-mass": None, "ur5e-reach": "ur5e",
                      "ur5e-reach-avoid": "ur5e"}


def test_rendered_frames_show_robot_and_target(arm_rollout):
    from envs import render

    policy, config, records = arm_rollout
    env = envs.make("ur5e-reach", **{**ARM_ENV, "workspace": "front"})
    frames = render.rollout_frames(env, records, width=160, height=120, hold=2)
    assert frames.shape == (config.episode_length + 1 + 2, 2 * 120, 2 * 160, 3)
    assert frames.dtype == np.uint8
    assert frames.std() > 10  # not blank
    assert not np.array_equal(frames[0], frames[-1])  # the arm moved
    with render.Scene(env, 160, 120) as scene:
        full = scene.draw(records["qpos"][0, 0], records["target_pos"][0, 0]).astype(int)
        scene.option.geomgroup[2] = 0  # hide the robot
        empty = scene.draw(records["qpos"][0, 0], records["target_pos"][0, 0]).astype(int)
    robot_pixels = np.any(np.abs(full - empty) > 30, axis=-1).sum()
    assert robot_pixels > 0.01 * 160 * 120
    green = (full[..., 1] > 150) & (full[..., 0] < 100) & (full[..., 2] < 100)
    assert green.sum() > 5  # the target marker


def test_cli_checkpoint_on_other_workspace_with_video(arm_export, arm_rollout, tmp_path):
    """`eval.py --checkpoint RUN --env.workspace front --json ... --video ...`; both compiled programs
    come from the tests above through the compilation cache."""
    out, video = tmp_path / "out.json", tmp_path / "rollout.gif"
    proc = _eval_cli("--checkpoint", str(arm_export), "--env.workspace", "front", "--num-envs", "4", "--json", str(out),
                     "--video", str(video), "--video-envs", "4", "--video-size", "160x120")
    assert proc.returncode == 0, proc.stderr[-3000:]
    report = json.loads(out.read_text())
    ev = report["evaluations"][0]
    assert report["env_overrides"] == {"workspace": "front"}
    assert ev["env_config"]["workspace"] == "front"
    assert ev["env_config"]["substeps"] == 2
    assert ev["policy"]["env_steps"] == 1280
    assert ev["policy"]["export"].endswith(os.path.join("1280", "policy"))
    from PIL import Image

    with Image.open(video) as gif:
        assert gif.n_frames >= 10
        assert gif.size == (320, 240)


# ------------------------------------------------------------------------------------------------
# Bad input: a ValueError with a one-line message, before anything compiles


@pytest.fixture
def no_compile(monkeypatch):
    """Evaluations are built (env, jitted function) but never run."""
    original = evaluation._evaluator.__wrapped__

    def building_only(*args):
        program = original(*args)
        return dataclasses.replace(program, evaluate=lambda *a, **k: pytest.fail("evaluated despite bad input"))

    monkeypatch.setattr(evaluation, "_evaluator", building_only)


def _corrupt(src, tmp_path, how):
    run = tmp_path / "corrupt"
    shutil.copytree(src, run)
    policy = max(run.glob("checkpoints/*/policy"), key=lambda p: int(p.parent.name))  # the newest: eval.py's pick
    if how == "npz":
        data = (policy / "policy.npz").read_bytes()
        (policy / "policy.npz").write_bytes(data[: len(data) // 2])
    elif how == "json":
        (policy / "policy.json").write_text("{not json")
    elif how == "shapes":
        with np.load(policy / "policy.npz") as f:
            arrays = {k: f[k] for k in f.files}
        arrays["policy/params/hidden_0/kernel"] = arrays["policy/params/hidden_0/kernel"][:, :, :7]
        np.savez(policy / "policy.npz", **arrays)
    elif how == "orbax":  # no export and a broken full checkpoint
        step = policy.parent
        shutil.rmtree(policy)
        (step / "state").mkdir(exist_ok=True)
        for f in (step / "state").rglob("*"):
            if f.is_file():
                f.write_bytes(b"garbage")
    return run


BAD = [
    (lambda d, t: ["--checkpoint", str(t / "nowhere")], r"does not exist"),
    (lambda d, t: ["--checkpoint", str(t)], r"holds no checkpoint and no policy export"),
    (lambda d, t: ["--checkpoint", str(_corrupt(d["arm"], t, "npz"))], r"corrupt or unreadable"),
    (lambda d, t: ["--checkpoint", str(_corrupt(d["arm"], t, "json"))], r"corrupt or unreadable: policy.json: JSONDecodeError"),
    (lambda d, t: ["--checkpoint", str(_corrupt(d["arm"], t, "shapes"))], r"do not match the network of its config"),
    (lambda d, t: ["--checkpoint", str(_corrupt(d["point"], t, "orbax"))], r"corrupt or unreadable"),
    (lambda d, t: ["--checkpoint", str(d["arm"]), "--env", "panda-reach"],
     r"trained on 'ur5e-reach' \(robot ur5e\): env='panda-reach' is another robot"),
    (lambda d, t: ["--checkpoint", str(d["point"]), "--env", "ur5e-reach"], r"is another robot"),
    (lambda d, t: ["--checkpoint", str(d["arm"]), "--env.observation", "joint_pos", "ee_pos"],
     r"takes observations of shape \(15,\) but env 'ur5e-reach' with observation=\('joint_pos', 'ee_pos'\) gives shape \(9,\)"),
    (lambda d, t: ["--checkpoint", str(d["arm"]), "--env", "ur5e-reach-avoid"],  # reach agent: own observation kept
     None),
    (lambda d, t: ["--checkpoint", str(d["arm"]), "--env", "ur5e-reach-avoid", "--env.observation", "joint_pos",
                   "ee_pos", "target_pos", "ee_to_target", "obstacle_pos"], r"shape \(15,\) .* gives shape \(18,\)"),
    # formerly the trained parts reordered, or another action mode, ran without a word
    (lambda d, t: ["--checkpoint", str(d["arm"]), "--env.observation", "ee_pos", "joint_pos", "target_pos", "ee_to_target"],
     r"cannot run with observation=\('ee_pos', 'joint_pos', 'target_pos', 'ee_to_target'\) \(trained: \('joint_pos', "
     r"'ee_pos', 'target_pos', 'ee_to_target'\)\): .*\(or --allow-env-mismatch"),
    (lambda d, t: ["--checkpoint", str(d["arm"]), "--env.action", "absolute"],
     r"cannot run with action='absolute' \(trained: 'relative'\)"),
    (lambda d, t: ["--checkpoint", str(d["arm"]), "--env.action", "absolute", "--allow-env-mismatch"], None),
    (lambda d, t: ["--checkpoint", str(d["point"] / "metrics.csv")], r"checkpoint '.*metrics.csv' is a file: allowed is"),
    (lambda d, t: ["--checkpoint", str(d["point"]), "--env.dim", "3"],
     r"takes observations of shape \(6,\) but env 'point-mass' gives shape \(9,\): allowed are env options giving "
     r"observations of shape \(6,\)"),
    (lambda d, t: ["--env", "ur5e-reach", "--policy", "ik"], r"policy='ik' is unknown: allowed are random, standstill, pseudo_ik"),
    (lambda d, t: ["--env", "ur5e-reach", "--policy", "pseudo_ik", "--env.target-sampling", "uniform"],
     r"pseudo_ik' is undefined with target_sampling='uniform'"),
    (lambda d, t: ["--env", "point-mass", "--policy", "pseudo_ik"], r"needs an arm environment"),
    (lambda d, t: ["--env", "ur5-reach", "--policy", "random"], r"env='ur5-reach' is unknown: allowed are"),
    (lambda d, t: ["--policy", "random"], r"--policy needs --env NAME"),
    (lambda d, t: ["--env", "point-mass", "--policy", "random", "--stochastic"], r"--stochastic is invalid with --policy random"),
    (lambda d, t: ["--env", "point-mass", "--policy", "random", "--compute-dtype", "float32"],
     r"--compute-dtype is invalid with --policy random"),
    (lambda d, t: ["--checkpoint", str(t / "nowhere"), "--compute-dtype", "float16"],  # refused before loading
     r"--compute-dtype='float16' is invalid: allowed are float32, bfloat16"),
    (lambda d, t: ["--checkpoint", str(d["point"]), "--compute-dtype", "bfloat16"],
     r"compute_dtype='bfloat16' is invalid for '.*' \(ppo, which has no compute_dtype setting\)"),
    (lambda d, t: ["--env", "ur5e-reach"], r"give exactly one of --checkpoint"),
    (lambda d, t: ["--env", "ur5e-reach", "--policy", "random", "--checkpoint", str(d["arm"])], r"give exactly one of"),
    (lambda d, t: ["--env", "ur5e-reach", "--policy", "random", "--num-envs", "0"], r"--num-envs=0 is invalid"),
    (lambda d, t: ["--env", "ur5e-reach", "--policy", "random", "--env.target-radius", "-1"], r"target_radius=-1.0 is invalid"),
    (lambda d, t: ["--env", "ur5e-reach", "--policy", "random", "--num-env", "4"], r"option '--num-env' is unknown"),
    (lambda d, t: ["--env", "point-mass", "--policy", "random", "--video", str(t / "v.gif")], r"--video needs an arm env"),
    (lambda d, t: ["--env", "ur5e-reach", "--policy", "random", "--video", str(t / "v.avi")], r"allowed are .mp4 and .gif"),
    (lambda d, t: ["--env", "ur5e-reach", "--policy", "random", "--video", str(t / "v.gif"), "--video-size", "big"],
     r"--video-size='big' is invalid"),
]


@pytest.mark.parametrize("make, message", BAD, ids=[f"bad{i}" for i in range(len(BAD))])
def test_bad_input_is_refused_with_a_clear_message(make, message, arm_export, point_run, tmp_path, no_compile):
    args = make({"arm": arm_export, "point": point_run}, tmp_path)
    if message is None:  # accepted: evaluation would start (and is stopped by the fixture)
        with pytest.raises(pytest.fail.Exception, match="evaluated despite bad input"):
            eval_cli.main(args + ["--num-envs", "2"])
        return
    with pytest.raises(ValueError, match=message) as info:
        eval_cli.main(args)
    assert "\n" not in str(info.value)


def test_mismatch_allowed_with_a_warning_naming_both(arm_export, no_compile):
    with pytest.warns(UserWarning, match=r"evaluated with action='absolute' \(trained: 'relative'\)"):
        with pytest.raises(pytest.fail.Exception, match="evaluated despite bad input"):
            eval_cli.main(["--checkpoint", str(arm_export), "--env.action", "absolute", "--allow-env-mismatch",
                           "--num-envs", "2"])


def test_damaged_export_is_rebuilt_from_the_full_checkpoint(point_run, tmp_path, capsys):
    """A damaged policy export with its full checkpoint beside it is written anew."""
    run = _corrupt(point_run, tmp_path, "npz")
    policy = evaluation.checkpoint_policy(str(run))
    err = capsys.readouterr().err
    assert "policy.npz: " in err, err
    assert "rebuilding it from the full checkpoint" in err, err
    original = export.load(str(point_run))
    for a, b in zip(jax.tree.leaves(original.state), jax.tree.leaves(policy.export.state)):
        np.testing.assert_array_equal(np.asarray(a), np.asarray(b))
    export.load(str(run))  # readable again


def test_help_lists_the_env_options_once_the_env_is_known(arm_export, capsys):
    """`eval.py --help`: eval.py's options; with a checkpoint (or --env): also its env's --env.<field>."""
    for args, env_option in ((["--help"], None), (["--checkpoint", str(arm_export), "--help"], "--env.workspace"),
                             (["--env", "point-mass", "-h"], "--env.episode-length")):
        with pytest.raises(SystemExit) as info:
            eval_cli.main(args)
        out = capsys.readouterr().out
        assert info.value.code == 0
        assert "--num-envs" in out
        assert "--checkpoint" in out
        assert ("--env.episode-length" in out) == (env_option is not None)
        assert env_option is None or env_option in out


def test_bad_option_values_exit_2():
    with pytest.raises(SystemExit) as info:  # tyro: not a workspace
        eval_cli.main(["--env", "ur5e-reach", "--policy", "random", "--env.workspace", "everywhere"])
    assert info.value.code == 2


def test_cli_error_is_one_line_with_exit_code_2(tmp_path):
    proc = _eval_cli("--checkpoint", str(tmp_path / "missing"), "--json", str(tmp_path / "o.json"))
    assert proc.returncode == 2
    assert proc.stderr.strip().count("\n") == 0
    assert proc.stderr.startswith("error: checkpoint ")
    assert "Traceback" not in proc.stderr
    assert not (tmp_path / "o.json").exists()


# ------------------------------------------------------------------------------------------------
# Pictures


def test_training_curves_from_train_logs(point_run, tmp_path):
    from tools import plots

    steps, mean, std, seeds = plots.curve([str(point_run)], "episode/target_reached")
    rows = plots.read_metrics(str(point_run))
    assert seeds == 2
    assert list(steps) == [5120, 10240]
    at_end = rows["episode/target_reached"][rows["env_steps"] == 10240]
    np.testing.assert_allclose(mean[-1], at_end.mean())
    np.testing.assert_allclose(std[-1], at_end.std())
    out = tmp_path / "curves.png"
    fig = plots.training_curves({"ppo": str(point_run)}, out=str(out))
    assert out.stat().st_size > 10_000
    assert len(fig.axes) == 2  # target reached and return (point mass has no collisions)
    assert [t.get_text() for t in fig.legends[0].get_texts()] == ["ppo (2 seeds)"]
    renderer = fig.canvas.get_renderer()
    legend_box = fig.legends[0].get_window_extent(renderer)
    assert legend_box.x0 > fig.axes[-1].get_window_extent(renderer).x1  # beside the panels, over no curve
    assert legend_box.x1 < fig.bbox.x1  # the figure widened to hold it
    with pytest.raises(ValueError, match="metrics.csv"):
        plots.read_metrics(str(tmp_path))


def test_training_curves_against_wall_clock(tmp_path):
    from tools import plots

    # Two seeds logged over three chunks; the x value is the seeds' mean running sum of chunk times.
    rows = [(100, 0, 2.0, 0.1), (100, 1, 4.0, 0.3), (200, 0, 1.0, 0.5), (200, 1, 1.0, 0.7),
            (300, 0, 3.0, 0.9), (300, 1, 1.0, 0.9)]
    (tmp_path / "metrics.csv").write_text("env_steps,seed,steps_per_second,wall_seconds,episode/target_reached\n"
                                          + "".join(f"{s},{d},1.0,{w},{v}\n" for s, d, w, v in rows))
    seconds, mean, _, seeds = plots.curve(str(tmp_path), "episode/target_reached", x="wall_clock")
    np.testing.assert_allclose(seconds, [3.0, 4.0, 6.0])  # seed 0: 2, 3, 6; seed 1: 4, 5, 6
    np.testing.assert_allclose(mean, [0.2, 0.6, 0.9])
    assert seeds == 2
    # Only the first seed (a run sharing a larger run's part): seed 0's values and clock alone.
    seconds, mean, std, seeds = plots.curve(str(tmp_path), "episode/target_reached", x="wall_clock",
                                            keep={str(tmp_path): 1})
    np.testing.assert_allclose(seconds, [2.0, 3.0, 6.0])
    np.testing.assert_allclose(mean, [0.1, 0.5, 0.9])
    assert seeds == 1
    assert not std.any()
    fig = plots.training_curves({"run": str(tmp_path)}, ["episode/target_reached"], x="wall_clock")
    assert fig.axes[0].get_xlabel() == plots.X_AXES["wall_clock"]
    with pytest.raises(ValueError, match="x='minutes'.*env_steps, wall_clock"):
        plots.curve(str(tmp_path), "episode/target_reached", x="minutes")
    # A run resumed from its step-100 checkpoint logs steps 200 and 300 again (4 s each): they replace the first rows.
    with open(tmp_path / "metrics.csv", "a") as f:
        f.write("200,0,1.0,4.0,0.5\n300,0,1.0,4.0,0.7\n200,1,1.0,4.0,0.5\n300,1,1.0,4.0,0.7\n")
    seconds, mean, _, _ = plots.curve(str(tmp_path), "episode/target_reached", x="wall_clock")
    np.testing.assert_allclose(seconds, [3.0, 7.0, 11.0])  # seed 0: 2, 6, 10; seed 1: 4, 8, 12
    np.testing.assert_allclose(mean, [0.2, 0.5, 0.7])


def test_paper_tables_from_given_checkpoints_and_skips_the_rest(point_run, tmp_path, capsys):
    from tools import paper_tables

    written = paper_tables.main(["--tables", "action", "workspace", "obstacle", "--out", str(tmp_path),
                                 "--num-envs", "16", "--action", f"relative={point_run}"])
    assert [os.path.basename(p) for p in written] == ["action_space.md"]
    err = capsys.readouterr().err
    assert "skipped table 'workspace'" in err
    assert "skipped table 'obstacle'" in err
    assert "no 'absolute' checkpoint given, row skipped" in err
    text = (tmp_path / "action_space.md").read_text()
    assert "| Relative | 2 x 16 |" in text
    assert "Position" not in text
    assert str(point_run) in text
    assert "device: CPU" in text
    assert "--action relative=" in text
    data = json.loads((tmp_path / "action_space.json").read_text())
    assert data["rows"][0]["role"] == "relative"
    assert data["rows"][0]["policy"]["env_steps"] == 10240
    with pytest.raises(ValueError, match="role 'diagonal' is unknown"):
        paper_tables.main(["--tables", "workspace", "--workspace", f"diagonal={point_run}", "--out", str(tmp_path)])


def test_paper_tables_evaluate_each_pair_on_the_right_env_config(arm_export, tmp_path, monkeypatch):
    """The workspace and obstacle cross-evaluations: which env config each (trained, evaluated) row
    gets (evaluation itself replaced by a recorder)."""
    from tools import paper_tables

    calls = []

    def record(policy, env_name, config, num_envs, eval_seeds, last_steps=10, progress=None):
        calls.append((policy.name, env_name, config))
        per_env = {k: np.zeros((1, 2)) for k in ("target_reached", "self_collision", "obstacle_collision", "distance")}
        return evaluation.Result(policy, env_name, config, 2, list(eval_seeds), 10, [{"metrics": {}}], per_env, 0.0)

    monkeypatch.setattr(evaluation, "run", record)
    front = _untrained_export(tmp_path / "front", workspace="front", init_range="limited")
    full = _untrained_export(tmp_path / "full", init_range="limited")
    paper_tables.main(["--tables", "workspace", "--out", str(tmp_path), "--workspace", f"front={front}", f"full={full}"])
    rows = [(name.split("/")[-2], cfg.workspace, cfg.target_sampling, cfg.init_range) for name, _, cfg in calls]
    assert rows == [
        ("front", "front", "reachable", "limited"), ("full", "full", "reachable", "limited"),  # own workspace
        ("front", "full", "reachable", "limited"),  # the paper's "Full" agent: limited initial range
        ("front", "pandagym", "uniform", "limited"), ("full", "pandagym", "uniform", "limited"),
        ("full", "upper", "reachable", "limited"), ("full", "full", "reachable", "full"),  # -> "Full Range"
    ]
    table = (tmp_path / "workspace_generalization.md").read_text()
    assert "| Front | Full | 1 x 2 |" in table
    assert "| Full | Full Range | 1 x 2 |" in table

    calls.clear()
    avoid = _untrained_export(tmp_path / "avoid", "ur5e-reach-avoid", obstacle_radius=0.1, target_radius=0.02)
    paper_tables.main(["--tables", "obstacle", "--out", str(tmp_path), "--obstacle", f"0.1={avoid}",
                       f"reach={arm_export}"])
    got = [(name.split("/")[-2], env_name, cfg.obstacle_radius, cfg.target_radius, len(cfg.observation))
           for name, env_name, cfg in calls]
    assert got[0] == ("avoid", "ur5e-reach-avoid", 0.1, 0.02, 6)
    # The reach agent on the reach-avoid env: its own 4-part observation, the reach-avoid runs' target.
    reach = arm_export.parent.name  # arm0, or arm1 where the worker made another "arm" folder first
    assert got[1:] == [(reach, "ur5e-reach-avoid", r, 0.02, 4) for r in (0.025, 0.05, 0.1, 0.2, 0.3)]
    assert calls[1][2].substeps == 2  # the reach checkpoint's own settings otherwise


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


# ------------------------------------------------------------------------------------------------
# tools/failure_report.py: episode outcomes from recorded poses (CPU MuJoCo as the reference)


def test_failure_report_names_the_colliding_pair_and_bins_the_misses(monkeypatch):
    from tools import failure_report

    monkeypatch.setattr(failure_report, "END_STEPS", 2)  # end_motion from 2 steps before each episode's end

    robot = envs.make("ur5e-reach").robot
    model = contact_model(robot)
    free = np.zeros(robot.nq, np.float32)
    free[1], free[2] = -1.2, 1.0  # elbow bent, clear of the base
    assert not colliding_pairs(model, free)
    hit = colliding_configuration(robot, seed=15)
    expected = {" / ".join(sorted((model.geom(a).name, model.geom(b).name))) for a, b in colliding_pairs(model, hit)}
    steps, n = 6, 4
    qpos = np.tile(free, (steps + 1, n, 1))
    qpos[3:, 1] = hit  # env 1 collides at step 3 (its recorded poses stay there)
    qpos[4:, 2, 1] = robot.joint_high[1] - 0.01  # env 2 misses with its shoulder-lift joint pinned at the limit
    qpos[4:, 3, 1] = robot.joint_low[1] + 0.2  # env 3 misses 0.2 rad from the other limit: not at it
    metrics = {"episode/self_collision": np.array([0, 1, 0, 0.0]), "episode/obstacle_collision": np.zeros(n),
               "episode/target_reached": np.array([1, 0, 0, 0.0]), "episode/distance": np.array([0.005, 0.3, 0.07, 0.5])}
    records = {"qpos": qpos, "length": np.array([6, 3, 6, 6]), "metrics": metrics}
    rows = failure_report.classify(robot, records)
    assert [r["outcome"] for r in rows] == ["reached", "self collision", "missed", "missed"]
    assert " / ".join(sorted(rows[1]["what"].split(" / "))) in expected
    assert rows[1]["step"] == 3
    assert rows[0]["start_clearance"] > 0
    summary = failure_report.summarize(rows)
    assert summary["outcomes"] == {"missed": 0.5, "reached": 0.25, "self collision": 0.25}
    assert summary["missed_final_distance"] == {"0-2 cm": 0, "2-5 cm": 0, "5-10 cm": 1, "> 10 cm": 1}
    assert summary["collisions"]["step_quartiles"] == [3.0, 3.0, 3.0]
    assert "self collision: " + rows[1]["what"] in failure_report.markdown(summary, "t")
    shoulder = robot.mj_model.joint(1).name
    assert [r["at_limit"] for r in rows] == [[], [], [shoulder], []]
    assert summary["ending_at_a_joint_limit"] == {"missed": 0.5, "reached": 0.0, "self collision": 0.0}
    assert summary["missed_by_joint_at_limit"] == {shoulder: 1}
    # margins: 0.01 and 0.2 rad as set; the end effector (CPU MuJoCo) moved from the free pose to the collision
    # in env 1's last 2 steps (steps 1-3) and stood still in env 2's (steps 4-6)
    np.testing.assert_allclose([rows[2]["joint_margin"], rows[3]["joint_margin"]], [0.01, 0.2], atol=1e-5)
    assert rows[0]["joint_margin"] > failure_report.NEAR_LIMIT
    moved = np.linalg.norm(ee_position(robot.mj_model, hit) - ee_position(robot.mj_model, free))
    np.testing.assert_allclose([rows[1]["end_motion"], rows[2]["end_motion"]], [moved, 0.0], atol=1e-5)
    assert summary["end"]["missed"]["near_limit"] == 1.0
    assert summary["end"]["reached"]["near_limit"] == 0.0
    assert failure_report.summarize(rows, near_limit=0.1)["end"]["missed"]["near_limit"] == 0.5  # 0.01 only


def _free_arm_and_target(steps: int = 4, n: int = 2):
    """The UR5e reach-avoid robot, a pose clear of itself (elbow bent), its end effector (CPU MuJoCo) and a target
    0.4 m beside it, recorded for `steps` + 1 steps of `n` envs."""
    robot = envs.make("ur5e-reach-avoid").robot
    free = np.zeros(robot.nq, np.float32)
    free[1], free[2] = -1.2, 1.0
    ee = ee_position(robot.mj_model, free)
    return robot, free, ee, np.tile(ee + [0.4, 0.0, 0.0], (steps + 1, n, 1))


def _clearances(robot, qpos, centre, radius):
    """CPU MuJoCo's distance from each of the robot's obstacle geoms to a sphere (`mj_geomDistance`)."""
    import mujoco

    model = contact_model(robot, obstacle_radius=radius)
    data = mujoco.MjData(model)
    data.qpos[:] = qpos
    data.mocap_pos[robot.obstacle_mocap] = centre
    mujoco.mj_kinematics(model, data)
    return np.array([mujoco.mj_geomDistance(model, data, model.geom("obstacle").id, int(g), 1.0, None)
                     for g in robot.obstacle_geoms])


def test_failure_report_follows_several_moving_obstacles_of_their_own_radii():
    """Two obstacles of radius 0.05 and 0.12 m that move: env 0's small one sits on the straight line to the target
    at the start and leaves it, the large one ends near the arm; env 1's large one ends on a link (an obstacle
    collision). The nearest surfaces at the end come from CPU MuJoCo, one sphere at a time."""
    from tools import failure_report

    robot, free, ee, target = _free_arm_and_target()
    steps, n = 4, 2
    small = np.tile(ee + [0.2, 0.0, 0.0], (steps + 1, n, 1))
    small[1:] += [0.0, 0.5, 0.0]  # off the line from step 1
    large = np.tile(ee + [0.0, 0.0, 0.5], (steps + 1, n, 1))
    large[steps, 0] = ee + [0.0, 0.0, 0.2]  # 0.2 m above the end effector at the end
    large[2:, 1] = ee  # env 1: on the end effector from step 2, where its episode ends
    radii = np.tile([0.05, 0.12], (steps + 1, n, 1))
    metrics = {"episode/self_collision": np.zeros(n), "episode/obstacle_collision": np.array([0.0, 1.0]),
               "episode/target_reached": np.zeros(n), "episode/distance": np.array([0.4, 0.4])}
    records = {"qpos": np.tile(free, (steps + 1, n, 1)), "target_pos": target,
               "obstacle_pos": np.concatenate([small, large], axis=-1), "obstacle_radius": radii,
               "length": np.array([steps, 2]), "metrics": metrics}
    rows = failure_report.classify(robot, records)
    assert [r["outcome"] for r in rows] == ["missed", "obstacle collision"]
    assert rows[0]["obstacle_between"] == {"start": True, "end": False}
    for i, last in enumerate((steps, 2)):
        expected = np.minimum(_clearances(robot, free, small[last, i], 0.05), _clearances(robot, free, large[last, i], 0.12))
        np.testing.assert_allclose(rows[i]["final_obstacle_clearance"], expected.min(), atol=1e-4)
    nearest = robot.obstacle_geoms[int(np.argmin(_clearances(robot, free, ee, 0.12)))]
    assert rows[1]["what"] == robot.mj_model.geom(int(nearest)).name
    assert "obstacle_after_target" not in failure_report.summarize(rows)["collisions"]  # no steps_in_target recorded


def test_failure_report_names_the_base_when_moving_obstacles_are_checked_against_it():
    """An obstacle of radius 0.05 m 0.1 m below the base sphere's centre (radius 0.075) overlaps only the base: the
    report names it among the geoms a moving-obstacle env checks (`checked_geoms`), and cannot among the pairs'."""
    from tools import failure_report

    robot, free, _, target = _free_arm_and_target(n=1)
    moving = envs.make("ur5e-reach-avoid", num_obstacles=1, obstacle_motion="linear")
    base = int(robot.mj_model.geom("base").id)
    centre = np.asarray(robot.kinematics(free).geom_xpos)[base] + [0.0, 0.0, -0.1]
    metrics = {"episode/self_collision": np.zeros(1), "episode/obstacle_collision": np.ones(1),
               "episode/target_reached": np.zeros(1), "episode/distance": np.array([0.4])}
    records = {"qpos": np.tile(free, (5, 1, 1)), "target_pos": target, "obstacle_pos": np.tile(centre, (5, 1, 1)),
               "length": np.array([4]), "metrics": metrics}
    row, = failure_report.classify(robot, records, obstacle_radius=0.05, geoms=moving.checked_geoms)
    assert row["what"] == "base"
    np.testing.assert_allclose(row["final_obstacle_clearance"], 0.1 - 0.075 - 0.05, atol=1e-5)
    assert failure_report.classify(robot, records, obstacle_radius=0.05)[0]["what"] != "base"


def test_failure_report_tells_whose_motion_brought_an_obstacle_collision(monkeypatch):
    """Four obstacle collisions, each asked over its last 3 steps: an obstacle that comes down onto a still arm and an
    arm that swings its end effector into a still obstacle (both ending at step 4, so asked from step 1); an arm and
    an obstacle that each move only part of the way (ending at step 2, shorter than the window: asked from the reset,
    both needed); an obstacle on
    a still end effector all along (either alone). Step 1 alone is away in the first two envs, so a window one step
    off either way finds the contact there and answers "either"."""
    from tools import failure_report

    monkeypatch.setattr(failure_report, "APPROACH_STEPS", 3)
    robot, hit_pose, ee, target = _free_arm_and_target(n=4)
    away_pose = hit_pose.copy()
    away_pose[0] += 1.0  # the shoulder pan turned 1 rad: the end effector about half a metre to the side
    above = ee + [0.0, 0.0, 0.4]
    assert _clearances(robot, away_pose, ee, 0.05).min() > 0.1  # the swung-away arm is clear of the contact point
    assert _clearances(robot, hit_pose, above, 0.05).min() > 0.1  # and the arm clear of the point above it
    steps = 4
    qpos = np.tile(hit_pose, (steps + 1, 4, 1))
    obstacle = np.tile(ee, (steps + 1, 4, 1))
    obstacle[1, 0] = above  # env 0: the obstacle is away at step 1 only
    qpos[1, 1] = away_pose  # env 1: the arm is away at step 1 only
    qpos[0, 2], obstacle[0, 2] = away_pose, above  # env 2: both away at step 0, its window's start
    metrics = {"episode/self_collision": np.zeros(4), "episode/obstacle_collision": np.ones(4),
               "episode/target_reached": np.zeros(4), "episode/distance": np.full(4, 0.4),
               "episode/steps_in_target": np.array([0.0, 2.0, 0.0, 5.0])}  # envs 1 and 3 had reached the target
    records = {"qpos": qpos, "target_pos": target, "obstacle_pos": obstacle, "length": np.array([4, 4, 2, 4]),
               "metrics": metrics}
    rows = failure_report.classify(robot, records, obstacle_radius=0.05)
    assert [r["approach"] for r in rows] == ["obstacle", "arm", "both", "either"]
    assert [r["steps_in_target"] for r in rows] == [0, 2, 0, 5]
    summary = failure_report.summarize(rows)
    assert summary["collisions"]["obstacle_approach"] == {"obstacle": 1, "arm": 1, "both": 1, "either": 1}
    assert summary["collisions"]["approach_steps"] == 3
    assert summary["collisions"]["obstacle_after_target"] == 2
    assert summary["collisions"]["obstacle_approach_after_target"] == {"arm": 1, "either": 1}
    assert "had reached the target: 2 (arm 1, either 1)" in failure_report.markdown(summary, "t")
    assert "in_target_before" not in rows[0]  # no target radius given
    np.testing.assert_allclose(rows[1]["approach_clearances"]["arm_held"],
                               _clearances(robot, away_pose, ee, 0.05).min(), atol=1e-4)


def test_failure_report_tells_whether_the_arm_was_in_its_target_on_the_step_before_an_obstacle_collision():
    """All three envs collide at step 3. Env 0's target lies 2 cm from the end effector of a still arm (CPU MuJoCo);
    env 1's on it, the arm swung away on the colliding step only; env 2's on it, the arm away on the step before
    only. With a target radius of 1 cm only env 1 was in the target on step 2; with 3 cm envs 0 and 1."""
    from tools import failure_report

    robot, free, ee, target = _free_arm_and_target(steps=3, n=3)
    target[:, 0], target[:, 1:] = ee + [0.02, 0.0, 0.0], ee
    away = free.copy()
    away[0] += 1.0  # the shoulder pan turned 1 rad: the end effector about half a metre aside
    qpos = np.tile(free, (4, 3, 1))
    qpos[3, 1], qpos[2, 2] = away, away
    metrics = {"episode/self_collision": np.zeros(3), "episode/obstacle_collision": np.ones(3),
               "episode/target_reached": np.zeros(3), "episode/distance": np.zeros(3)}
    records = {"qpos": qpos, "target_pos": target, "obstacle_pos": np.tile(ee, (4, 3, 1)),
               "length": np.array([3, 3, 3]), "metrics": metrics}
    rows = failure_report.classify(robot, records, obstacle_radius=0.05, target_radius=0.01)
    assert [r["in_target_before"] for r in rows] == [False, True, False]
    assert failure_report.summarize(rows)["collisions"]["obstacle_in_target_before"] == 1
    wider = failure_report.classify(robot, records, obstacle_radius=0.05, target_radius=0.03)
    assert [r["in_target_before"] for r in wider] == [True, True, False]


def test_point_segment_distance_on_hand_computed_geometry():
    """What failure_report's obstacle_between measures: a sphere's clearance from the end effector's
    straight line to the target (`envs.collision.point_segment_distance` minus the radius)."""
    from envs import collision

    a, b = np.zeros(3), np.array([1.0, 0.0, 0.0])
    centers = np.array([[0.5, 0.3, 0.0], [0.5, 0.05, 0.0], [1.5, 0.0, 0.0], [-0.3, 0.4, 0.0]])
    # beside the middle: 0.3 - 0.1; through the line: 0.05 - 0.1; past b: 0.5 - 0.1; behind a: 0.5 - 0.1
    np.testing.assert_allclose(collision.point_segment_distance(centers, a, b) - 0.1, [0.2, -0.05, 0.4, 0.4], atol=1e-6)
    np.testing.assert_allclose(collision.point_segment_distance(np.array([0.0, 0.0, 0.3]), a, a) - 0.1, 0.2, atol=1e-6)


def test_failure_report_tells_when_the_obstacle_is_in_the_way():
    """The end effector's position comes from CPU MuJoCo; the obstacle sits on the straight line to the
    target in env 1 (which misses) and beside it in env 0 (which reaches)."""
    import mujoco

    from tools import failure_report

    robot, free, ee, target = _free_arm_and_target()
    steps, n = 4, 2
    obstacle = np.tile(ee + [0.2, 0.0, 0.0], (steps + 1, n, 1))
    obstacle[:, 0] = ee + [0.2, 0.3, 0.0]  # 0.3 m beside the line: clear of a 0.1 m sphere
    metrics = {"episode/self_collision": np.zeros(n), "episode/obstacle_collision": np.zeros(n),
               "episode/target_reached": np.array([1.0, 0.0]), "episode/distance": np.array([0.005, 0.4])}
    records = {"qpos": np.tile(free, (steps + 1, n, 1)), "target_pos": target, "obstacle_pos": obstacle,
               "length": np.array([steps, steps]), "metrics": metrics}
    rows = failure_report.classify(robot, records, obstacle_radius=0.1)
    assert [r["obstacle_between"] for r in rows] == [{"start": False}, {"start": True, "end": True}]
    # the robot's clearance from the obstacle: CPU MuJoCo's distance between the obstacle sphere and the robot
    model = contact_model(robot, obstacle_radius=0.1)
    data = mujoco.MjData(model)
    for i, row in enumerate(rows):
        data.qpos[:] = free
        data.mocap_pos[robot.obstacle_mocap] = obstacle[0, i]
        mujoco.mj_kinematics(model, data)
        obstacle_geom = model.geom("obstacle").id
        expected = min(mujoco.mj_geomDistance(model, data, obstacle_geom, int(g), 1.0, None)
                       for g in robot.obstacle_geoms)
        np.testing.assert_allclose(row["final_obstacle_clearance"], expected, atol=1e-4)
    # env 0's obstacle (0.3 m aside of the line) overlaps a link of this pose; env 1's clears the arm by 6 cm
    assert rows[0]["final_obstacle_clearance"] < 0 < rows[1]["final_obstacle_clearance"] < 0.1
    summary = failure_report.summarize(rows)
    assert summary["obstacle_between_at_start"] == {"missed": 1.0, "reached": 0.0}
    assert summary["missed_obstacle_between_at_end"] == 1.0
    assert summary["final_obstacle_clearance"]["missed"]["median"] == rows[1]["final_obstacle_clearance"]
    assert "missed episodes ending with it there: 100.0 %" in failure_report.markdown(summary, "t")
    assert "obstacle_between" not in failure_report.classify(robot, records)[0]  # no radius given: not asked
    assert [r["target_height"] for r in rows] == list(target[0, :, 2])
    np.testing.assert_allclose([r["start_distance"] for r in rows], [0.4, 0.4], atol=1e-5)  # target 0.4 m along x
    assert summary["start_distance_median"]["missed"] == rows[1]["start_distance"]


def test_failure_report_bins_outcomes_by_target_height():
    """Hand-sorted: heights on a bin edge go to the bin above it; empty bins are left out."""
    from tools import failure_report

    heights = [-0.05, 0.02, 0.05, 0.1, 0.25, 0.6, 0.7]
    outcomes = ["missed", "missed", "reached", "reached", "self collision", "reached", "reached"]
    rows = [{"target_height": h, "outcome": o} for h, o in zip(heights, outcomes)]
    bins = failure_report.outcomes_by_height(rows)
    assert bins == {
        "< 0 cm": {"episodes": 1, "missed": 1.0, "reached": 0.0, "self collision": 0.0},
        "0-10 cm": {"episodes": 2, "missed": 0.5, "reached": 0.5, "self collision": 0.0},
        "10-30 cm": {"episodes": 2, "missed": 0.0, "reached": 0.5, "self collision": 0.5},
        "> 50 cm": {"episodes": 2, "missed": 0.0, "reached": 1.0, "self collision": 0.0},
    }
    text = failure_report.markdown({"episodes": 7, "outcomes": {}, "ending_at_a_joint_limit": {},
                                    "by_target_height": bins}, "t")
    assert "| 0-10 cm | 2 | 50.0 % | 50.0 % | 0.0 % |" in text


def test_failure_report_json_names_what_made_it(tmp_path, monkeypatch):
    """--json carries the command, code, device and date (agents/provenance.py); the rollout and its reading are
    stubbed: only the shipped policy's export is loaded."""
    from agents import provenance
    from tools import failure_report

    monkeypatch.delenv(provenance.COMMAND_VARIABLE, raising=False)
    monkeypatch.setattr(evaluation, "rollout", lambda *a, **k: None)
    monkeypatch.setattr(failure_report, "classify", lambda *a, **k: [])
    monkeypatch.setattr(failure_report, "summarize", lambda rows, near_limit=None: {"episodes": 0})
    monkeypatch.setattr(failure_report, "markdown", lambda summary, title: "")
    out, checkpoint = tmp_path / "report.json", os.path.join(ROOT, "results", "checkpoints", "ur5e-reach-ppo")
    failure_report.main(["--checkpoint", checkpoint, "--num-envs", "1", "--json", str(out)])
    report = json.loads(out.read_text())
    assert report["command"] == shlex.join(["python", "-m", "tools.failure_report", "--checkpoint", checkpoint,
                                            "--num-envs", "1", "--json", str(out)])
    assert report["code"] == provenance.code_version()
    assert report["device"] == provenance.device_description()
    assert report["date"] == datetime.date.today().isoformat()


def test_failure_report_reads_the_code_version_before_rewriting_its_file(tmp_path, monkeypatch):
    """A report that rewrites a tracked file must not find the tree modified by its own rewrite: the code version is
    read before the file is opened (here the stubbed version is what the file holds when it is read)."""
    from agents import provenance
    from tools import failure_report

    monkeypatch.setattr(evaluation, "rollout", lambda *a, **k: None)
    monkeypatch.setattr(failure_report, "classify", lambda *a, **k: [])
    monkeypatch.setattr(failure_report, "summarize", lambda rows, near_limit=None: {"episodes": 0})
    monkeypatch.setattr(failure_report, "markdown", lambda summary, title: "")
    out, checkpoint = tmp_path / "report.json", os.path.join(ROOT, "results", "checkpoints", "ur5e-reach-ppo")
    out.write_text("the report of an earlier run")
    monkeypatch.setattr(provenance, "code_version", lambda: out.read_text())
    failure_report.main(["--checkpoint", checkpoint, "--num-envs", "1", "--json", str(out)])
    assert json.loads(out.read_text())["code"] == "the report of an earlier run"


def test_a_part_observed_at_one_value_in_training_is_refused_where_it_changes():
    """A static-obstacle agent that observed obstacle_vel (always 0) saw it as one value: its normaliser, variance
    0, scales any motion to the clip (0 % reached where it reached 80 %: results/experiments/obstacles-moving3).
    Evaluating it on moving obstacles is refused (warned with allow_env_mismatch); the agent trained on moving
    obstacles may be evaluated on static ones, whose zero velocity it saw within its range."""
    from types import SimpleNamespace

    observation = ("joint_pos", "ee_pos", "target_pos", "obstacle_pos", "obstacle_radius", "obstacle_vel")
    options = dict(num_obstacles=2, obstacle_radius_range=(0.05, 0.1), observation=observation, substeps=2)
    static = envs.make("panda-reach-avoid", obstacle_motion="static", **options)
    moving = envs.make("panda-reach-avoid", obstacle_motion="linear", **options)

    def trained_on(env):
        e = SimpleNamespace(env_name="panda-reach-avoid", config=SimpleNamespace(env=env.config),
                            observation_size=env.observation_size, action_size=env.action_size)
        return evaluation.Policy("checkpoint", "run", [0], export=e)

    with pytest.raises(ValueError, match=r"cannot be evaluated fairly here: it observes obstacle_vel \(trained with "
                                         r"obstacle_motion='static', here varying\)\. .*--allow-env-mismatch"):
        evaluation.check_compatible(trained_on(static), "panda-reach-avoid", moving)
    with pytest.warns(UserWarning, match=r"observes obstacle_vel .* scales to the clip"):
        evaluation.check_compatible(trained_on(static), "panda-reach-avoid", moving, allow_env_mismatch=True)
    evaluation.check_compatible(trained_on(moving), "panda-reach-avoid", static)
    evaluation.check_compatible(trained_on(static), "panda-reach-avoid", static)
    # A fixed radius observed in training, evaluated at another: the same refusal.
    fixed = envs.make("panda-reach-avoid", **{**options, "obstacle_radius_range": None})
    bigger = envs.make("panda-reach-avoid", **{**options, "obstacle_radius_range": None, "obstacle_radius": 0.2})
    with pytest.raises(ValueError, match=r"obstacle_radius \(trained with obstacle radius 0.1 m, here obstacle radius "
                                         r"0.2 m\)"):
        evaluation.check_compatible(trained_on(fixed), "panda-reach-avoid", bigger)
