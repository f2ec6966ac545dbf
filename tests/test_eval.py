"""eval.py and its library (agents.evaluation): metric aggregation on hand-built episodes, evaluation of a checkpoint
on another workspace, rollouts and restarts, rendering, and which trained settings an evaluation may change.

CPU cost is dominated by compiling MJX rollouts (~25 s each on 2 cores), so every compiled evaluation is shared:
module-scoped fixtures (`arm_export`: conftest.py), and eval.py subprocesses run the same programs as the in-process
tests with the persistent compilation cache (`.jax_cache/`, see conftest.py) switched on. Also: test_eval_exports.py
(policy exports), test_eval_input.py (refused input), test_baselines.py, test_plots_and_tables.py,
test_failure_report.py.
"""

import json
import os
from types import SimpleNamespace

import jax
import jax.numpy as jnp
import numpy as np
import pytest

import envs
from agents import evaluation
from agents.loop import episode_metrics
from eval_runs import ARM_ENV, eval_process
from mujoco_reference import colliding_configuration


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


# ------------------------------------------------------------------------------------------------
# A checkpoint on another workspace (an untrained UR5e policy written as the driver writes exports)


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
    proc = eval_process("--checkpoint", str(arm_export), "--env.workspace", "front", "--num-envs", "4", "--json", str(out),
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


def test_a_part_observed_at_one_value_in_training_is_refused_where_it_changes():
    """A static-obstacle agent that observed obstacle_vel (always 0) saw it as one value: its normaliser, variance
    0, scales any motion to the clip (0 % reached where it reached 80 %: results/experiments/obstacles-moving3).
    Evaluating it on moving obstacles is refused (warned with allow_env_mismatch); the agent trained on moving
    obstacles may be evaluated on static ones, whose zero velocity it saw within its range."""
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
