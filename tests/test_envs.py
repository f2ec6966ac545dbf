"""Behaviour of the four arm environments: jit/vmap, determinism, sampling, rewards, metrics,
truncation versus termination and NaN handling. CPU references come from CPU MuJoCo. Actions and the integrator:
tests/test_env_actions.py; observation parts and refused options: tests/test_env_options.py.

Compiled functions are shared per environment through a module-scoped cache: compiling an MJX
step takes ~20 s on a 2-core CPU.
"""

import os

import jax
import jax.numpy as jnp
import numpy as np
import pytest

import envs
from envs import rewards, workspaces
from envs.arm import METRICS
from mujoco_reference import colliding_configuration, colliding_pairs, contact_model, ee_position

ARM_ENVS = ["ur5e-reach", "panda-reach", "ur5e-reach-avoid", "panda-reach-avoid"]
N = 4


class Compiled:
    """One wrapped environment with its jitted reset and step."""

    def __init__(self, name, **options):
        self.env = envs.make(name, **options)
        self.batched = envs.wrap(self.env)
        self.reset = jax.jit(self.batched.reset)
        self.step = jax.jit(self.batched.step)
        self.raw_reset = jax.jit(jax.vmap(self.env.reset))

    def start(self, seed, n=N):
        return self.reset(jax.random.split(jax.random.PRNGKey(seed), n))

    def starts(self, seed, batches):
        """`batches` x N start states from the compiled reset of N envs (one program for every sample size),
        stacked along the batch axis."""
        states = [self.start(seed * 1000 + i) for i in range(batches)]
        return jax.tree.map(lambda *leaves: np.concatenate([np.asarray(x) for x in leaves]), *states)


@pytest.fixture(scope="module")
def compiled():
    cache = {}

    def get(name, **options):
        key = (name, tuple(sorted(options.items())))
        if key not in cache:
            cache[key] = Compiled(name, **options)
        return cache[key]

    return get


def standstill(env, n=N):
    return jnp.zeros((n, env.action_size))  # relative control: hold the current pose


@pytest.mark.parametrize("name", ARM_ENVS)
def test_jit_vmap_determinism_and_sizes(compiled, name):
    c = compiled(name)
    state = c.start(seed=0)
    assert state.obs.shape == (N, c.env.observation_size)
    assert c.env.action_size == (6 if name.startswith("ur5e") else 7)
    again = c.start(seed=0)
    np.testing.assert_array_equal(state.obs, again.obs)  # same key, same episode
    other = c.start(seed=1)
    assert not np.allclose(state.obs, other.obs)
    assert len({tuple(np.round(o, 5)) for o in np.asarray(state.obs)}) == N  # envs differ
    actions = jax.random.uniform(jax.random.PRNGKey(2), (N, c.env.action_size), minval=-1, maxval=1)
    after = c.step(state, actions)
    np.testing.assert_array_equal(after.obs, c.step(again, actions).obs)
    reward_terms = {"reward/" + term for term in c.env.reward_term_names()}
    assert set(after.metrics) == set(state.metrics) == set(METRICS) | reward_terms
    assert jax.tree.structure(after) == jax.tree.structure(state)
    assert np.isfinite(after.obs).all()
    assert np.isfinite(after.reward).all()
    assert not np.allclose(after.obs, state.obs)


GOLDEN = os.path.join(os.path.dirname(__file__), "golden_default_rollouts.npz")
"""Stored rollouts of the default envs (see the test below); `UPDATE_GOLDEN=1 pytest tests/test_envs.py -k golden`
rewrites the entries of the backend in use, for an intended change of the defaults only."""


@pytest.mark.parametrize("name", ARM_ENVS)
def test_default_envs_reproduce_their_golden_rollout(compiled, name):
    """The default envs (the paper's options) reproduce a stored rollout: 4 envs of seed 0 through the training
    stack, 3 steps of fixed random actions; observations, rewards and joint positions. Options added later (more
    obstacles, noise, latency, backends) must leave the defaults as they were."""
    c = compiled(name)
    state = c.start(seed=0)
    got = {"obs0": state.obs}
    for t in range(1, 4):
        actions = jax.random.uniform(jax.random.PRNGKey(100 + t), (N, c.env.action_size), minval=-1, maxval=1)
        state = c.step(state, actions)
        got.update({f"obs{t}": state.obs, f"reward{t}": state.reward, f"qpos{t}": state.pipeline_state.qpos})
    prefix = f"{c.env.backend}/{name}/"
    stored = dict(np.load(GOLDEN)) if os.path.exists(GOLDEN) else {}
    if os.environ.get("UPDATE_GOLDEN"):
        stored.update({prefix + k: np.asarray(v) for k, v in got.items()})
        np.savez(GOLDEN, **stored)
        pytest.skip(f"rewrote {prefix}* in {GOLDEN}")
    if not any(k.startswith(prefix) for k in stored):
        pytest.skip(f"no golden rollout for {prefix} (backend {c.env.backend}): UPDATE_GOLDEN=1 writes one")
    for key, value in got.items():
        np.testing.assert_allclose(np.asarray(value), stored[prefix + key], atol=1e-4, err_msg=prefix + key)


@pytest.mark.parametrize("name", ["ur5e-reach", "panda-reach"])
def test_initial_poses_collision_free_and_in_range(compiled, name):
    c = compiled(name)
    state = c.starts(3, 16)  # 64 envs
    model = contact_model(c.env.robot)
    qpos = np.asarray(state.pipeline_state.qpos)
    assert (qpos >= c.env.robot.joint_low - 1e-6).all()
    assert (qpos <= c.env.robot.joint_high + 1e-6).all()
    assert float(state.metrics["reset_fallback"].max()) == 0.0
    for q in qpos:
        assert not colliding_pairs(model, q)


def test_limited_initial_range_ur5e(compiled):
    c = compiled("ur5e-reach", init_range="limited")
    qpos = np.asarray(c.starts(4, 16).pipeline_state.qpos)  # 64 envs
    assert np.abs(qpos).max() <= np.pi + 1e-6
    full = np.asarray(compiled("ur5e-reach").starts(4, 16).pipeline_state.qpos)
    assert np.abs(full).max() > np.pi  # the full range really uses +-2 pi


@pytest.mark.parametrize("workspace", ["full", "front", "upper"])
def test_reachable_targets_inside_workspace_and_reached_by_their_pose(compiled, workspace):
    c = compiled("ur5e-reach", workspace=workspace)
    state = c.starts(5, 12)  # 48 envs
    robot = c.env.robot
    model = contact_model(robot)
    targets = np.asarray(state.info["target_pos"])
    inside = workspaces.contains(workspace, jnp.asarray(targets), robot.workspace_center, robot.reach)
    assert np.asarray(inside).all()
    for target, q in zip(targets, np.asarray(state.info["target_qpos"])):
        np.testing.assert_allclose(ee_position(model, q), target, atol=1e-4)  # FK on CPU MuJoCo
        assert not colliding_pairs(model, q)  # the pose that reaches it is collision free
    if workspace == "front":
        assert (targets[:, 0] >= 0).all()
    if workspace == "upper":
        assert (targets[:, 2] >= 0).all()


def test_uniform_pandagym_targets_fill_the_cube(compiled):
    c = compiled("panda-reach", workspace="pandagym", target_sampling="uniform")
    targets = np.asarray(c.raw_reset(jax.random.split(jax.random.PRNGKey(6), 256)).info["target_pos"])
    assert (targets >= workspaces.PANDAGYM_LOW).all()
    assert (targets <= workspaces.PANDAGYM_HIGH).all()
    # Uniform in a 30 cm cube: mean at the centre, std 0.3 / sqrt(12) = 0.0866 per axis.
    np.testing.assert_allclose(targets.mean(0), (workspaces.PANDAGYM_LOW + workspaces.PANDAGYM_HIGH) / 2, atol=0.02)
    np.testing.assert_allclose(targets.std(0), 0.3 / np.sqrt(12), atol=0.012)


def test_uniform_workspace_sampler_geometry():
    center, reach = np.array([0.0, 0.0, 0.163], np.float32), 0.97
    for workspace in ("full", "front"):
        points, valid = workspaces.sample_uniform(workspace, jax.random.PRNGKey(7), 20000, center, reach)
        points = np.asarray(points)[np.asarray(valid)]
        radius = np.linalg.norm(points - center, axis=1)
        assert radius.max() <= reach + 1e-5
        # Uniform in a ball: P(r < R/2) = 1/8.
        assert abs(np.mean(radius < reach / 2) - 0.125) < 0.01
    front, _ = workspaces.sample_uniform("front", jax.random.PRNGKey(8), 1000, center, reach)
    assert (np.asarray(front)[:, 0] >= 0).all()
    _, valid = workspaces.sample_uniform("upper", jax.random.PRNGKey(9), 20000, center, reach)
    # Ball of radius R cut by a plane h = 0.163 below its centre: fraction above it
    # = 1 - pi (R - h)^2 (2R + h) / 3 / (4/3 pi R^3).
    h = 0.163
    expected = 1 - (reach - h) ** 2 * (2 * reach + h) / (4 * reach**3)
    assert 0.6 < expected < 0.7
    assert abs(float(np.mean(valid)) - expected) < 0.01


@pytest.mark.parametrize("name", ["ur5e-reach-avoid", "panda-reach-avoid"])
def test_obstacles_clear_of_initial_pose_and_target(compiled, name):
    c = compiled(name)
    cfg = c.env.config
    state = c.starts(10, 12)  # 48 envs
    model = contact_model(c.env.robot, obstacle_radius=cfg.obstacle_radius)
    obstacle = np.asarray(state.info["obstacle_pos"])
    assert (np.abs(obstacle) <= cfg.obstacle_region).all()
    gap = np.linalg.norm(obstacle - np.asarray(state.info["target_pos"]), axis=1)
    assert (gap > cfg.obstacle_radius + cfg.target_radius).all()
    for q, o in zip(np.asarray(state.pipeline_state.qpos), obstacle):
        assert not colliding_pairs(model, q, obstacle_pos=o)


def test_reward_formulas_hand_computed():
    # Dense, paper eq. (2): exp(-20 * 0.05) = 0.36788.
    assert np.isclose(rewards.dense(0.05, 1.0, 20.0), 0.3678794, atol=1e-6)
    assert np.isclose(rewards.dense(0.0, 2.0, 20.0), 2.0)
    # Semi-sparse, eq. (1): in target, w_reach 1, w_dist 0.5, d_max 0.85, d 0.01 -> 1 + 0.5 * 1.69.
    assert np.isclose(rewards.semi_sparse(1.0, 0.01, 1.0, 0.5, 0.85), 1.845)
    assert np.isclose(rewards.semi_sparse(0.0, 0.7, 1.0, 1.0, 0.85), 1.0)
    assert np.isclose(rewards.sparse(1.0, 3.0), 3.0)
    assert rewards.sparse(0.0) == 0.0
    # Obstacle proximity, eq. (3): tau 0.1; distances 0.05, 0.2, -0.01 -> 0.5 + 0 + 1.1; w 0.1.
    assert np.isclose(rewards.obstacle_proximity(jnp.array([0.05, 0.2, -0.01]), 0.1, 0.1), 0.16, atol=1e-6)
    # L2 penalty: ||(3, 4)|| = 5.
    assert np.isclose(rewards.l2_penalty(jnp.array([3.0, 4.0]), 0.01), 0.05)
    # Joint-limit proximity: ranges [-1, 1] and [0, 2], margin 0.4; joints 0.9 (0.1 from the upper end:
    # 1 - 0.25) and 1.0 (1.0 from both: 0) -> 0.75; at a limit the full weight; weight 2.
    low, high = jnp.array([-1.0, 0.0]), jnp.array([1.0, 2.0])
    assert np.isclose(rewards.joint_limit_proximity(jnp.array([0.9, 1.0]), low, high, 2.0, 0.4), 1.5, atol=1e-6)
    assert np.isclose(rewards.joint_limit_proximity(jnp.array([-1.0, 0.0]), low, high, 2.0, 0.4), 4.0, atol=1e-6)


TERMINATE = dict(success="reach_and_terminate", reward="semi_sparse")  # one extra compiled variant


@pytest.mark.parametrize("options", [{}, TERMINATE], ids=["dense", "semi_sparse"])
def test_step_reward_matches_formula(compiled, options):
    c = compiled("ur5e-reach", **options)
    state = c.step(c.start(seed=11), standstill(c.env))
    d = np.asarray(state.metrics["distance"])
    in_target = np.asarray(state.metrics["in_target"])
    expected = np.exp(-20 * d) if not options else in_target + (2 * c.env.robot.reach - d)
    np.testing.assert_allclose(state.reward, expected, rtol=1e-5, atol=1e-6)


def test_sparse_and_penalised_rewards():
    env = envs.make("ur5e-reach", reward="sparse", w_reach=2.0)
    state = env.reset(jax.random.PRNGKey(0))
    data = state.pipeline_state.replace(qvel=jnp.full(6, 0.5), qacc=jnp.full(6, 2.0))
    assert float(env.reward(data, 0.005, 1.0, state.info)) == 2.0
    assert float(env.reward(data, 0.5, 0.0, state.info)) == 0.0
    env = envs.make("ur5e-reach", w_joint_vel=0.1, w_joint_acc=0.01)
    # exp(-20 * 0.1) - 0.1 * ||0.5 * 1_6|| - 0.01 * ||2 * 1_6|| = 0.135335 - 0.122474 - 0.048990
    np.testing.assert_allclose(env.reward(data, 0.1, 0.0, state.info), 0.1353353 - 0.1224745 - 0.0489898, atol=1e-6)
    # Joint-limit penalty, UR5e ranges +-2 pi (elbow +-pi), margin 0.3: the shoulder pan 0.1 rad below 2 pi
    # (1 - 1/3) and the elbow 0.15 above -pi (1 - 1/2), the rest at 0 -> 0.5 * (2/3 + 1/2) = 0.583333.
    env = envs.make("ur5e-reach", w_joint_limit=0.5, joint_limit_margin=0.3)
    data = data.replace(qpos=jnp.array([2 * np.pi - 0.1, 0.0, -np.pi + 0.15, 0.0, 0.0, 0.0]))
    np.testing.assert_allclose(env.reward(data, 0.1, 0.0, state.info), 0.1353353 - 0.5833333, atol=1e-5)
    with pytest.raises(ValueError, match="w_joint_limit"):
        envs.make_config("ur5e-reach", w_joint_limit=-1.0)
    with pytest.raises(ValueError, match="joint_limit_margin"):
        envs.make_config("ur5e-reach", joint_limit_margin=0.0)


def test_reward_terms_name_the_formulation_and_each_weighted_penalty():
    assert envs.make("ur5e-reach").reward_term_names() == ("dense",)
    env = envs.make("ur5e-reach-avoid", w_joint_vel=0.01, w_joint_limit=0.5, collision_penalty=2.0)
    assert env.reward_term_names() == ("semi_sparse", "joint_vel", "joint_limit", "obstacle", "collision")


def test_logged_reward_terms_add_up_to_each_episodes_return():
    """reward/<term> metrics are per-episode sums of the terms a step really earned (a colliding step: only
    the collision penalty), so at every step they add up to the return so far. 12 native envs, relative
    steps of up to 1 rad at random: some collide (checked) and pay the penalty of 2."""
    env = envs.make("ur5e-reach-avoid", backend="mujoco", action_scale=1.0, w_joint_vel=0.01, w_joint_limit=0.5,
                    collision_penalty=2.0, episode_length=40)
    batch = envs.wrap(env, autoreset=False)
    step = jax.jit(batch.step)
    state = batch.reset(jax.random.split(jax.random.PRNGKey(5), 12))
    names = ["reward/" + n for n in env.reward_term_names()]
    returns, alive, collided, penalty = np.zeros(12), np.ones(12, bool), np.zeros(12, bool), np.zeros(12)
    for t in range(40):
        state = step(state, jax.random.uniform(jax.random.PRNGKey(t), (12, 6), minval=-1.0, maxval=1.0))
        returns += np.where(alive, np.asarray(state.reward), 0.0)
        logged = sum(np.asarray(state.metrics[n]) for n in names)
        np.testing.assert_allclose(logged[alive], returns[alive], rtol=1e-5, atol=1e-4, err_msg=f"step {t}")
        ended = alive & (np.asarray(state.done) > 0)
        collided |= ended & (np.asarray(state.metrics["self_collision"] + state.metrics["obstacle_collision"]) > 0)
        penalty = np.where(ended, np.asarray(state.metrics["reward/collision"]), penalty)
        alive &= ~ended
    assert collided.any()
    np.testing.assert_allclose(penalty[collided], -2.0)


def test_a_penalty_is_one_entry():
    """The recipe of docs/adding_a_robot.md: a subclass adds a term to `penalties`; it is subtracted from the
    reward and named among the terms. exp(-20 * 0.1) - 0.3 * ||ctrl - qpos||_1 with |ctrl - qpos| = 0.2 rad."""
    class EffortPenalised(envs.Reach):
        def penalties(self):
            effort = lambda data, info: 0.3 * jnp.sum(jnp.abs(data.ctrl - data.qpos))
            return {**super().penalties(), "effort": (0.3, effort)}

    env = EffortPenalised(envs.ROBOTS["ur5e"](), envs.make_config("ur5e-reach"))
    state = env.reset(jax.random.PRNGKey(0))
    data = state.pipeline_state.replace(ctrl=state.pipeline_state.qpos + jnp.array([0.2, -0.2, 0.0, 0.0, 0.0, 0.0]))
    assert env.reward_term_names() == ("dense", "effort")
    np.testing.assert_allclose(env.reward(data, 0.1, 0.0, state.info), 0.1353353 - 0.12, atol=1e-6)


def test_reach_avoid_reward_includes_obstacle_penalty(compiled):
    c = compiled("ur5e-reach-avoid")
    env, cfg, robot = c.env, c.env.config, c.env.robot
    state = jax.tree.map(lambda x: x[0], c.start(seed=12))
    data = state.pipeline_state
    # Obstacle centre 0.08 m + radius above the second link's frame origin: d_i = 0.08 there.
    xpos = np.asarray(data.xpos)[robot.link_bodies]
    obstacle = xpos[1] + np.array([0.0, 0.0, cfg.obstacle_radius + 0.08])
    info = {**state.info, "obstacle_pos": jnp.asarray(obstacle, jnp.float32)}
    link_d = np.linalg.norm(xpos - obstacle, axis=-1) - cfg.obstacle_radius
    assert np.isclose(link_d[1], 0.08, atol=1e-5)
    penalty = cfg.w_obst * np.maximum(0, 1 - link_d / cfg.obstacle_tau).sum()
    assert penalty >= cfg.w_obst * 0.2 - 1e-6
    distance = 0.3
    reward = env.reward(data, jnp.float32(distance), jnp.float32(0.0), info)
    assert np.isclose(float(reward), (2 * robot.reach - distance) - penalty, atol=1e-5)
    obs = env.observation(data, data.xpos, data.site_xpos[robot.ee_site], info)
    np.testing.assert_allclose(obs[-len(robot.link_bodies):], link_d, atol=1e-5)  # last obs part


def test_truncation_after_episode_length_is_not_termination(compiled):
    c = compiled("ur5e-reach")
    state = c.start(seed=13)
    for _ in range(c.env.config.episode_length - 1):
        state = c.step(state, standstill(c.env))
    assert float(state.done.max()) == 0.0, "standstill must neither collide nor time out early"
    assert (np.asarray(state.info["steps"]) == c.env.config.episode_length - 1).all()
    final = c.step(state, standstill(c.env))
    np.testing.assert_array_equal(final.done, 1.0)
    np.testing.assert_array_equal(final.info["truncation"], 1.0)
    np.testing.assert_array_equal(final.info["steps"], 0)  # a new episode has started...
    assert not np.allclose(final.info["target_pos"], state.info["target_pos"])  # ...freshly sampled
    assert not np.allclose(final.obs, final.info["final_obs"])  # terminal obs kept for bootstrapping


def _with_target(state, target):
    return state.replace(info={**state.info, "target_pos": jnp.asarray(target, jnp.float32)})


def _next_ee(c, state):
    """End-effector position after a standstill step (the motion does not depend on the target)."""
    return np.asarray(c.step(state, standstill(c.env)).pipeline_state.site_xpos)[:, c.env.robot.ee_site]


def test_collision_terminates_without_truncation_and_hand_built_metrics(compiled):
    """Reach, leave, re-enter, then collide: metrics as counted by hand."""
    c = compiled("ur5e-reach")
    still = standstill(c.env)
    s0 = c.start(seed=14)
    s1 = c.step(_with_target(s0, _next_ee(c, s0)), still)  # step 1 ends in the target
    assert (s1.metrics["in_target"] == 1).all()
    assert (s1.metrics["target_reached"] == 1).all()
    s2 = c.step(_with_target(s1, _next_ee(c, s1) + np.array([0.1, 0, 0])), still)  # 10 cm off: left once
    assert (s2.metrics["in_target"] == 0).all()
    assert (s2.metrics["times_left_target"] == 1).all()
    np.testing.assert_allclose(s2.metrics["distance"], 0.1, atol=1e-4)
    assert (s2.metrics["target_reached"] == 1).all()  # reached once stays reached
    s3 = c.step(_with_target(s2, _next_ee(c, s2)), still)  # back in
    np.testing.assert_array_equal(s3.metrics["steps_in_target"], 2)
    np.testing.assert_array_equal(s3.metrics["times_left_target"], 1)
    mean3 = sum(np.asarray(s.metrics["distance"]) for s in (s1, s2, s3)) / 3  # fewer than 10 steps so far
    np.testing.assert_allclose(s3.metrics["distance_last10"], mean3, rtol=1e-5)
    # Step 4: jump into a colliding configuration -> termination, not truncation; not reached.
    q = colliding_configuration(c.env.robot, seed=15)
    data = s3.pipeline_state.replace(qpos=jnp.tile(q, (N, 1)), qvel=jnp.zeros_like(s3.pipeline_state.qvel))
    s4 = c.step(s3.replace(pipeline_state=data), still)
    np.testing.assert_array_equal(s4.metrics["self_collision"], 1)
    np.testing.assert_array_equal(s4.done, 1)
    np.testing.assert_array_equal(s4.info["truncation"], 0)
    np.testing.assert_array_equal(s4.metrics["target_reached"], 0)  # a collision voids the reach
    np.testing.assert_array_equal(s4.metrics["steps_in_target"], 2)
    np.testing.assert_array_equal(s4.reward, 0)


def test_joint_speed_and_acceleration_metrics_are_episode_means_restarted_by_a_reset(compiled):
    """`mean_joint_vel` / `mean_joint_acc`: the mean over the episode's steps of ||qvel|| / ||qacc|| at each step's
    end, by a plain-Python sum; the step after a termination (auto-reset) starts a new mean."""
    c = compiled("ur5e-reach")
    state = c.start(seed=22)
    actions = jax.random.uniform(jax.random.PRNGKey(23), (4, N, c.env.action_size), minval=-1, maxval=1)
    vel, acc = [], []
    for k in range(4):
        state = c.step(state, actions[k])
        vel.append(np.linalg.norm(np.asarray(state.pipeline_state.qvel), axis=-1))
        acc.append(np.linalg.norm(np.asarray(state.pipeline_state.qacc), axis=-1))
        assert float(state.done.max()) == 0.0
        np.testing.assert_allclose(state.metrics["mean_joint_vel"], sum(vel) / (k + 1), rtol=1e-4)
        np.testing.assert_allclose(state.metrics["mean_joint_acc"], sum(acc) / (k + 1), rtol=1e-4)
    assert (acc[-1] > 1.0).all()
    assert not np.allclose(acc[0], acc[-1])  # moving: the means are not trivially 0
    q = colliding_configuration(c.env.robot, seed=15)
    data = state.pipeline_state.replace(qpos=jnp.tile(q, (N, 1)), qvel=jnp.zeros_like(state.pipeline_state.qvel))
    ended = c.step(state.replace(pipeline_state=data), standstill(c.env))
    np.testing.assert_array_equal(ended.done, 1)
    assert float(ended.metrics["mean_joint_acc"].min()) > 0  # the ended episode's mean, as evaluation reads it
    np.testing.assert_array_equal(ended.info["mean_joint_acc"], 0)  # the episode the auto-reset began
    np.testing.assert_array_equal(ended.info["mean_joint_vel"], 0)
    vel, acc = [], []
    for k in range(2):  # two steps: a mean the old episode's values would shift
        ended = c.step(ended, actions[k])
        vel.append(np.linalg.norm(np.asarray(ended.pipeline_state.qvel), axis=-1))
        acc.append(np.linalg.norm(np.asarray(ended.pipeline_state.qacc), axis=-1))
    np.testing.assert_allclose(ended.metrics["mean_joint_vel"], (vel[0] + vel[1]) / 2, rtol=1e-4)
    np.testing.assert_allclose(ended.metrics["mean_joint_acc"], (acc[0] + acc[1]) / 2, rtol=1e-4)


def test_running_mean_by_hand():
    from envs.arm import ArmEnv

    assert float(ArmEnv.running_mean(2.0, 5.0, 3, False)) == 3.0  # (2 + 2 + 5) / 3
    assert float(ArmEnv.running_mean(2.0, 5.0, 3, True)) == 2.0  # a NaN step adds nothing
    assert float(ArmEnv.running_mean(2.0, np.inf, 3, False)) == 2.0
    assert float(ArmEnv.running_mean(0.0, 4.0, 1, False)) == 4.0


def test_obstacle_collision_terminates(compiled):
    c = compiled("ur5e-reach-avoid")
    state = c.start(seed=16)
    ee = np.asarray(state.pipeline_state.site_xpos)[:, c.env.robot.ee_site]
    state.info["obstacle_pos"] = jnp.asarray(ee, jnp.float32)
    after = c.step(state, standstill(c.env))
    np.testing.assert_array_equal(after.metrics["obstacle_collision"], 1)
    np.testing.assert_array_equal(after.done, 1)


def test_reach_and_terminate_ends_episode_in_target(compiled):
    c = compiled("ur5e-reach", **TERMINATE)
    state = c.start(seed=17)
    after = c.step(_with_target(state, _next_ee(c, state)), standstill(c.env))
    np.testing.assert_array_equal(after.done, 1)
    np.testing.assert_array_equal(after.info["truncation"], 0)
    np.testing.assert_array_equal(after.metrics["target_reached"], 1)


def test_nan_physics_ends_episode_and_never_reaches_obs(compiled):
    c = compiled("ur5e-reach")
    state = c.start(seed=18)
    qvel = state.pipeline_state.qvel.at[0, 1].set(jnp.nan)
    after = c.step(state.replace(pipeline_state=state.pipeline_state.replace(qvel=qvel)), standstill(c.env))
    assert float(after.metrics["physics_nan"][0]) == 1
    assert float(after.done[0]) == 1
    assert float(after.metrics["physics_nan"][1:].max()) == 0
    assert np.isfinite(after.obs).all()
    assert np.isfinite(after.info["final_obs"]).all()
    assert np.isfinite(after.pipeline_state.qpos).all()  # auto-reset replaced the broken state


def test_nan_action_ends_episode_with_the_last_finite_distance(compiled):
    """Before the fix, the NaN step's distance metrics were NaN, so every average over episodes was NaN."""
    c = compiled("ur5e-reach")
    state = c.start(seed=18)
    actions = standstill(c.env).at[0].set(jnp.nan)
    after = c.step(state, actions)
    assert float(after.metrics["physics_nan"][0]) == 1
    assert float(after.done[0]) == 1
    np.testing.assert_allclose(after.metrics["distance"][0], state.metrics["distance"][0])  # the last finite value
    np.testing.assert_allclose(after.metrics["distance_last10"][0], state.metrics["distance"][0], rtol=1e-6)
    assert np.isfinite(after.reward).all()
    assert np.isfinite(after.info["final_obs"]).all()
