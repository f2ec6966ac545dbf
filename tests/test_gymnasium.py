"""The Gymnasium bridge (envs/gymnasium.py): spaces, SAME_STEP autoreset, terminated vs truncated,
final observations, seeding, Gymnasium's env checker, and Stable-Baselines3 training through it.

Semantics are checked on `point-mass`, whose dynamics are simple enough to predict each step
(a zero action keeps the point still; leaving the arena terminates; 50 steps truncate); one UR5e
reach-avoid test runs the real physics (2 envs, 2 substeps)."""

import warnings

import jax
import numpy as np
import pytest

gym = pytest.importorskip("gymnasium", reason="gymnasium is in the gym and dev extras")
from gymnasium.utils.env_checker import check_env  # noqa: E402

import envs  # noqa: E402
from envs import gymnasium as eg  # noqa: E402

ARENA, DT, ALPHA, LIMIT = 1.5, 0.1, 5.0, 50  # PointMassConfig defaults


def _pm_reward(obs):
    """Point-mass reward of an observation (position, goal, goal - position) inside the arena."""
    return np.exp(-ALPHA * np.linalg.norm(obs[..., 4:6], axis=-1))


def test_spaces_metadata_and_reset():
    vec = eg.make_vec("point-mass", 3)
    assert isinstance(vec, gym.vector.VectorEnv)
    assert vec.num_envs == 3
    assert vec.episode_length == LIMIT
    assert vec.metadata["autoreset_mode"] is gym.vector.AutoresetMode.SAME_STEP
    assert vec.single_observation_space == gym.spaces.Box(-np.inf, np.inf, (6,), np.float32)
    assert vec.single_action_space == gym.spaces.Box(-1.0, 1.0, (2,), np.float32)
    assert vec.observation_space.shape == (3, 6)
    assert vec.action_space.shape == (3, 2)
    assert np.all(vec.action_space.low == -1)
    assert np.all(vec.action_space.high == 1)
    obs, infos = vec.reset(seed=0)
    assert obs.dtype == np.float32
    assert obs in vec.observation_space
    assert infos == {}
    np.testing.assert_allclose(obs[:, 4:6], obs[:, 2:4] - obs[:, 0:2], atol=1e-6)  # goal - position
    assert np.all(np.abs(obs[:, :4]) <= 1.0)  # start and goal sampled in [-1, 1]^2
    assert np.unique(obs[:, 0]).size == 3  # independent episodes


def test_truncation_at_time_limit_delivers_final_obs_and_restarts():
    vec = eg.make_vec("point-mass", 3)
    obs0, _ = vec.reset(seed=1)
    zeros = np.zeros((3, 2), np.float32)
    for t in range(1, LIMIT):
        obs, rewards, terminations, truncations, infos = vec.step(zeros)
        assert not terminations.any()
        assert not truncations.any()
        assert "final_obs" not in infos
        np.testing.assert_array_equal(obs, obs0)  # a zero action keeps the point where it is
        assert rewards.dtype == np.float32
        np.testing.assert_allclose(rewards, _pm_reward(obs0), rtol=1e-5)
        assert infos["_distance"].all()
        np.testing.assert_allclose(infos["distance"], np.linalg.norm(obs0[:, 4:6], axis=1), rtol=1e-5)

    obs, rewards, terminations, truncations, infos = vec.step(zeros)  # step 50: time limit
    assert truncations.all()
    assert not terminations.any()
    assert terminations.dtype == truncations.dtype == np.bool_
    assert infos["_final_obs"].all()
    assert infos["_final_info"].all()
    assert infos["final_obs"].dtype == object
    np.testing.assert_array_equal(np.stack(infos["final_obs"]), obs0)  # the terminal observation
    np.testing.assert_allclose(rewards, _pm_reward(obs0), rtol=1e-5)  # reward of the ended step
    np.testing.assert_allclose(infos["final_info"]["distance"], np.linalg.norm(obs0[:, 4:6], axis=1), rtol=1e-5)
    assert infos["final_info"]["_distance"].all()
    assert not infos["_distance"].any()
    assert not infos["distance"].any()  # reset info is empty
    assert not np.any(np.all(obs == obs0, axis=1))  # fresh episodes already started (SAME_STEP)

    for t in range(1, LIMIT + 1):  # the new episodes run their full length again
        _, _, terminations, truncations, _ = vec.step(zeros)
        assert not terminations.any()
        assert truncations.all() == (t == LIMIT)
        assert truncations.any() == (t == LIMIT)
    assert vec._step_fn._cache_size() == 1  # one compilation for all steps (no retracing)


def test_leaving_the_arena_terminates_not_truncates():
    vec = eg.make_vec("point-mass", 4)
    obs, _ = vec.reset(seed=2)
    right = np.tile(np.array([1.0, 0.0], np.float32), (4, 1))
    ended = np.zeros(4, bool)
    for _ in range(26):  # from x >= -1 at 0.1 per step, every point leaves within 26 steps
        prev = obs
        obs, rewards, terminations, truncations, infos = vec.step(right)
        assert not truncations.any()
        if terminations.any():
            assert infos["_final_obs"].tolist() == terminations.tolist()
            for i in range(4):
                if terminations[i] and not ended[i]:  # first episodes (restarted ones may end again)
                    final = infos["final_obs"][i]
                    assert final[0] > ARENA >= prev[i, 0]  # it left in this very step
                    np.testing.assert_allclose(final[0], prev[i, 0] + DT, atol=1e-5)
                    assert rewards[i] == 0.0
                    assert infos["final_info"]["_distance"][i]
                    assert not infos["_distance"][i]
                    assert np.all(np.abs(obs[i, :4]) <= 1.0)
                elif not terminations[i]:
                    assert infos["final_obs"][i] is None
                    assert infos["_distance"][i]
                    assert not infos["final_info"]["_distance"][i]
        ended |= terminations
    assert ended.all()


def test_bridge_reproduces_the_batched_jax_env():
    """Same keys and actions: the bridge's numpy outputs are those of `envs.wrap(env)`."""
    n, seed = 3, 5
    vec = eg.make_vec("point-mass", n)
    obs, _ = vec.reset(seed=seed)
    batched = envs.wrap(envs.make("point-mass"))
    keys = jax.vmap(jax.random.PRNGKey)(np.arange(seed, seed + n, dtype=np.uint32))
    state = jax.jit(batched.reset)(keys)
    step = jax.jit(batched.step)
    np.testing.assert_array_equal(obs, np.asarray(state.obs))
    rng, dones = np.random.default_rng(0), 0
    for _ in range(60):
        actions = rng.uniform(-1, 1, (n, 2)).astype(np.float32)
        obs, rewards, terminations, truncations, infos = vec.step(actions)
        state = step(state, actions)
        np.testing.assert_array_equal(obs, np.asarray(state.obs))
        np.testing.assert_array_equal(rewards, np.asarray(state.reward))
        np.testing.assert_array_equal(terminations | truncations, np.asarray(state.done) > 0)
        np.testing.assert_array_equal(truncations, np.asarray(state.info["truncation"]) > 0)
        for i in np.flatnonzero(terminations | truncations):
            np.testing.assert_array_equal(infos["final_obs"][i], np.asarray(state.info["final_obs"][i]))
            dones += 1
    assert dones >= n  # every env restarted at least once (time limit 50)


def _rollout(vec, seed, steps=60):
    obs, _ = vec.reset(seed=seed)
    rng = np.random.default_rng(seed)
    out = [obs]
    for _ in range(steps):
        obs, rewards, terminations, truncations, infos = vec.step(rng.uniform(-1, 1, vec.action_space.shape))
        out += [obs, rewards, terminations, truncations]
        out += [infos["final_obs"][i] for i in np.flatnonzero(terminations | truncations)]
    return out


def test_seeding_is_reproducible():
    a, b = eg.make_vec("point-mass", 2), eg.make_vec("point-mass", 2)
    run_a, run_b = _rollout(a, seed=7), _rollout(b, seed=7)
    assert len(run_a) == len(run_b) > 4 * 60  # includes the autoresets of the 50-step limit
    for x, y in zip(run_a, run_b):
        np.testing.assert_array_equal(x, y)
    assert not np.array_equal(a.reset(seed=8)[0], b.reset(seed=7)[0])

    # Sub-environment i of a vector env seeded s samples the episode of a single env seeded s + i.
    single = eg.make("point-mass")
    vec_obs, _ = a.reset(seed=10)
    for i in range(2):
        np.testing.assert_array_equal(single.reset(seed=10 + i)[0], vec_obs[i])
    # A seed given as one int per sub-environment.
    np.testing.assert_array_equal(a.reset(seed=[11, 10])[0], vec_obs[::-1])

    # Unseeded resets continue deterministically from the last seed, and differ between episodes.
    a.reset(seed=3)
    first = a.reset()[0]
    a.reset(seed=3)
    np.testing.assert_array_equal(a.reset()[0], first)
    assert not np.array_equal(a.reset()[0], first)
    # Without any seed, two instances sample different episodes.
    assert not np.array_equal(eg.make_vec("point-mass", 2).reset()[0], eg.make_vec("point-mass", 2).reset()[0])


def test_reset_mask_restarts_only_the_selected_envs():
    vec = eg.make_vec("point-mass", 3)
    vec.reset(seed=4)
    for _ in range(5):
        obs, *_ = vec.step(np.full((3, 2), 0.5, np.float32))
    new, infos = vec.reset(seed=20, options={"reset_mask": np.array([False, True, False])})
    assert infos == {}
    np.testing.assert_array_equal(new[[0, 2]], obs[[0, 2]])
    np.testing.assert_array_equal(new[1], eg.make_vec("point-mass", 3).reset(seed=20)[0][1])
    for t in range(LIMIT - 5):  # the kept episodes keep their step count, the new one restarts
        _, _, _, truncations, _ = vec.step(np.zeros((3, 2), np.float32))
    assert truncations.tolist() == [True, False, True]


def test_invalid_arguments_are_rejected_at_the_boundary():
    with pytest.raises(ValueError, match="num_envs"):
        eg.make_vec("point-mass", 0)
    with pytest.raises(ValueError, match="unknown"):
        eg.make_vec("no-such-env", 2)
    vec = eg.make_vec("point-mass", 2)
    with pytest.raises(RuntimeError, match="reset"):
        vec.step(np.zeros((2, 2)))
    with pytest.raises(ValueError, match="seed"):
        vec.reset(seed=-1)
    with pytest.raises(ValueError, match="one per environment"):
        vec.reset(seed=[1, 2, 3])
    with pytest.raises(ValueError, match="options"):
        vec.reset(options={"difficulty": 2})
    vec.reset(seed=0)
    with pytest.raises(ValueError, match=r"\(2, 2\)"):
        vec.step(np.zeros((3, 2)))
    with pytest.raises(ValueError, match="reset_mask"):
        vec.reset(options={"reset_mask": np.array([0, 1])})


def test_step_after_close_says_the_env_is_closed():
    vec = eg.make_vec("point-mass", 2)
    vec.reset(seed=0)
    vec.close()
    with pytest.raises(RuntimeError, match=r"step\(\) after close\(\): this env is closed"):
        vec.step(np.zeros((2, 2)))


def test_string_actions_are_refused_naming_them():
    vec = eg.make_vec("point-mass", 2)
    vec.reset(seed=0)
    with pytest.raises(ValueError, match=r"actions='left' is invalid: allowed are numbers in \[-1, 1\]"):
        vec.step("left")


def test_single_env_string_action_is_refused_naming_it():
    env = eg.GymEnv(envs.make("point-mass"))
    env.reset(seed=0)
    with pytest.raises(ValueError, match=r"action=\['up', 'down'\] is invalid"):
        env.step(["up", "down"])


def test_rgb_array_render_draws_each_copy_of_an_arm():
    vec = eg.make_vec("ur5e-reach", 2, render_mode="rgb_array", substeps=2)
    vec.reset(seed=0)
    first, second = vec.render()
    assert first.shape[2] == 3
    assert first.dtype == np.uint8
    assert np.any(first != second)  # two sampled poses and targets, two pictures


def test_single_env_rgb_array_render_is_the_picture_of_its_state():
    env = eg.make("ur5e-reach", render_mode="rgb_array", substeps=2)
    env.reset(seed=0)
    frame = env.render()
    assert frame.ndim == 3
    assert frame.std() > 0  # not a blank image


def test_render_without_a_render_mode_returns_none():
    vec = eg.make_vec("point-mass", 2)
    vec.reset(seed=0)
    assert vec.render() is None


def test_rgb_array_is_refused_for_an_env_without_a_model():
    with pytest.raises(ValueError, match=r"render_mode='rgb_array' is invalid for PointMass"):
        eg.make_vec("point-mass", 2, render_mode="rgb_array")


def test_an_unknown_render_mode_is_refused():
    with pytest.raises(ValueError, match=r"render_mode='human' is invalid: allowed are None and 'rgb_array'"):
        eg.make_vec("ur5e-reach", 2, render_mode="human")


def test_gymnasium_env_checker_passes_on_the_single_env():
    env = eg.make("point-mass")
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        check_env(env, skip_render_check=True)
    # The only remarks allowed: observations are unbounded (joint velocities, positions out of the arena).
    remarks = [str(w.message) for w in caught if "infinity" not in str(w.message)]
    assert remarks == []

    obs, info = env.reset(seed=0)
    assert obs.shape == (6,)
    assert obs.dtype == np.float32
    assert info == {}
    for t in range(1, LIMIT + 1):
        next_obs, reward, terminated, truncated, info = env.step(np.zeros(2))
        assert type(reward) is float
        assert type(terminated) is bool
        assert type(truncated) is bool
        assert truncated == (t == LIMIT)
        assert not terminated
    np.testing.assert_array_equal(next_obs, obs)  # the terminal observation, not the next episode's
    assert set(info) == {"distance", "in_target", "target_reached", "physics_nan"}
    with pytest.raises(RuntimeError, match="reset"):
        env.step(np.zeros(2))


def test_gymnasium_env_checker_passes_on_the_native_arm_env():
    """The UR5e reach-avoid env on the native MuJoCo backend through Gymnasium's checker, and a few
    steps that move the arm (the physics really runs in C)."""
    env = eg.make("ur5e-reach-avoid", backend="mujoco", episode_length=5, sampling_candidates=4)
    assert env.vector_env.env.backend == "mujoco"
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        check_env(env, skip_render_check=True)
    assert [str(w.message) for w in caught if "infinity" not in str(w.message)] == []
    obs, _ = env.reset(seed=1)
    moved = obs
    for _ in range(3):
        moved, *_ = env.step(np.full(env.action_space.shape, 0.5, np.float32))
    assert np.abs(moved[:6] - obs[:6]).min() > 0.02  # every joint position (the first observation part) moved


def test_gymnasium_vector_wrappers_read_the_autoreset_mode():
    vec = gym.wrappers.vector.RecordEpisodeStatistics(eg.make_vec("point-mass", 2))
    vec.reset(seed=0)
    returns = np.zeros(2)
    for _ in range(LIMIT):
        _, rewards, _, truncations, infos = vec.step(np.zeros((2, 2), np.float32))
        returns += rewards
    assert truncations.all()
    assert infos["_episode"].all()
    np.testing.assert_array_equal(infos["episode"]["l"], [LIMIT, LIMIT])
    np.testing.assert_allclose(infos["episode"]["r"], returns, rtol=1e-5)


def test_ur5e_reach_avoid_through_the_bridge():
    vec = eg.make_vec("ur5e-reach-avoid", 2, episode_length=3, substeps=2, sampling_candidates=4)
    nq = 6  # observation: joint_pos, ee_pos, target_pos, ee_to_target, obstacle_pos, link distances
    ee, target, to_target = slice(nq, nq + 3), slice(nq + 3, nq + 6), slice(nq + 6, nq + 9)
    obs, _ = vec.reset(seed=0)
    vec.action_space.seed(0)
    assert obs.shape == (2, vec.env.observation_size)
    assert obs.dtype == np.float32
    assert np.isfinite(obs).all()
    np.testing.assert_allclose(obs[:, to_target], obs[:, target] - obs[:, ee], atol=1e-5)
    ended = np.zeros(2, bool)
    for t in range(1, 4):
        prev = obs
        obs, rewards, terminations, truncations, infos = vec.step(vec.action_space.sample())
        done = terminations | truncations
        assert np.isfinite(obs).all()
        assert np.isfinite(rewards).all()
        assert not (terminations & truncations).any()
        assert {"target_reached", "obstacle_collision", "self_collision", "distance_last10"} <= set(infos)
        assert truncations.tolist() == [t == 3 and not ended[i] for i in range(2)]  # 3-step limit
        for i in range(2):
            if not done[i]:  # the target stays put within an episode
                np.testing.assert_array_equal(obs[i, target], prev[i, target])
                continue
            final, final_info = infos["final_obs"][i], {k: v[i] for k, v in infos["final_info"].items()}
            np.testing.assert_array_equal(final[target], prev[i, target])  # the ended episode's state
            np.testing.assert_allclose(final_info["distance"], np.linalg.norm(final[to_target]), rtol=1e-4)
            assert not np.array_equal(obs[i, target], final[target])  # a fresh target is sampled
            failed = max(final_info["self_collision"], final_info["obstacle_collision"], final_info["physics_nan"])
            assert terminations[i] == (failed > 0)
        ended |= done
    assert ended.all()
    # A NaN action ends the episodes with finite metrics (else averages over episodes would be NaN).
    obs, rewards, terminations, _, infos = vec.step(np.full((2, nq), np.nan, np.float32))
    assert terminations.all()
    assert (infos["final_info"]["physics_nan"] == 1).all()
    for key in ("distance", "distance_last10"):
        assert np.isfinite(infos["final_info"][key]).all(), key
        assert (infos["final_info"][key] > 0).all(), key
    assert np.isfinite(obs).all()
    assert np.isfinite(rewards).all()


def test_nan_action_ends_the_point_mass_episode_like_the_arms():
    vec = eg.make_vec("point-mass", 3)
    obs, _ = vec.reset(seed=0)
    actions = np.zeros((3, 2), np.float32)
    actions[1, 0] = np.nan
    new, rewards, terminations, truncations, infos = vec.step(actions)
    assert terminations.tolist() == [False, True, False]
    assert not truncations.any()
    final = {k: v[1] for k, v in infos["final_info"].items()}
    assert final["physics_nan"] == 1
    assert np.isfinite(final["distance"])
    assert rewards[1] == 0
    np.testing.assert_array_equal(infos["final_obs"][1], obs[1])  # the point stayed where it was
    assert np.isfinite(new).all()
    assert (infos["physics_nan"] == 0).all()


def test_sb3_vec_env_adapter_reports_terminal_obs_and_time_limits():
    pytest.importorskip("stable_baselines3", reason="stable-baselines3 is in the dev extra")
    vec = eg.make_vec("point-mass", 2)
    sb3 = eg.to_sb3(vec)
    sb3.seed(3)
    obs = sb3.reset()
    np.testing.assert_array_equal(obs, eg.make_vec("point-mass", 2).reset(seed=3)[0])
    for t in range(1, LIMIT + 1):
        next_obs, rewards, dones, infos = sb3.step(np.zeros((2, 2), np.float32))
        assert dones.tolist() == [t == LIMIT] * 2
    for i in range(2):
        assert infos[i]["TimeLimit.truncated"] is True
        np.testing.assert_array_equal(infos[i]["terminal_observation"], obs[i])
        assert set(infos[i]) >= {"distance", "in_target", "target_reached"}
    assert not np.array_equal(next_obs, obs)
    right = np.tile(np.array([1.0, 0.0], np.float32), (2, 1))
    terminated = set()
    for _ in range(26):  # every point leaves the arena within 26 steps
        _, _, dones, infos = sb3.step(right)
        for i in np.flatnonzero(dones):
            assert infos[i]["TimeLimit.truncated"] is False
            assert infos[i]["terminal_observation"][0] > ARENA
            terminated.add(i)
    assert terminated == {0, 1}
    assert sb3.get_attr("render_mode") == [None, None]
    assert sb3.env_is_wrapped(gym.Wrapper) == [False, False]


def test_sb3_ppo_trains_through_the_bridge():
    sb3 = pytest.importorskip("stable_baselines3", reason="stable-baselines3 is in the dev extra")
    from stable_baselines3.common.env_checker import check_env as sb3_check_env
    from stable_baselines3.common.logger import Logger
    from stable_baselines3.common.vec_env import VecMonitor

    sb3_check_env(eg.make("point-mass"), warn=False)
    venv = VecMonitor(eg.to_sb3(eg.make_vec("point-mass", 4)), info_keywords=("target_reached",))
    model = sb3.PPO("MlpPolicy", venv, n_steps=64, batch_size=128, n_epochs=2, seed=0, device="cpu")
    model.set_logger(Logger(folder=None, output_formats=[]))  # else SB3 leaves an empty SB3-<date> folder in the temp folder
    model.learn(total_timesteps=512)
    assert model.num_timesteps >= 512
    episodes = list(model.ep_info_buffer)
    assert episodes
    assert all(0 < e["l"] <= LIMIT for e in episodes)
    assert all(e["target_reached"] in (0.0, 1.0) for e in episodes)
    actions, _ = model.predict(venv.reset(), deterministic=True)
    assert actions.shape == (4, 2)
    assert np.all(np.abs(actions) <= 1.0)
