"""The reach-avoid options beyond the paper: several obstacles, random radii, moving obstacles, observation noise and
action latency. Collisions against CPU MuJoCo with the obstacle spheres as geoms. Their configuration and the
trajectories: tests/test_obstacle_config.py.

Two compiled variants, shared by the module (2 physics substeps keep MJX's CPU compile short), each at one
batch size (a reset or step of another size would compile again).
"""

import jax
import jax.numpy as jnp
import mujoco
import numpy as np
import pytest

import envs
from mujoco_reference import ee_position, geom_poses, obstacle_contacts, obstacles_model
from obstacle_envs import N, Compiled, reflect_by_hand, split_obs, standstill

SENSING_N = 32
"""Envs per batch of the noise-and-latency variant (its noise statistics: 32 x 6 joint and 32 x 3 obstacle draws)."""
MOVING = dict(num_obstacles=3, obstacle_motion="linear", obstacle_radius_range=(0.05, 0.15), substeps=2,
              obstacle_speed_range=(0.05, 0.2),
              observation=("joint_pos", "ee_pos", "target_pos", "obstacle_pos", "obstacle_size", "obstacle_radius",
                           "obstacle_vel", "link_obstacle_dist", "link_obstacle_ahead"), obstacle_lookahead=(0.5, 2.0))
SENSING = dict(joint_noise_std=0.01, obstacle_noise_std=0.02, action_latency=1, substeps=2,
               observation=("joint_pos", "ee_pos", "target_pos", "ee_to_target", "obstacle_pos", "link_obstacle_dist",
                            "link_obstacle_ahead"))
BORDERLINE = 1e-4  # closer than this to touching: float32 against float64, skipped


@pytest.fixture(scope="module")
def moving():
    return Compiled(**MOVING)


@pytest.fixture(scope="module")
def sensing():
    return Compiled(**SENSING)


# ------------------------------------------------------------------------------------------------
# Sampling, collisions and observations of several moving obstacles


def test_sampled_obstacles_clear_of_start_pose_and_target(moving):
    env, cfg = moving.env, moving.env.config
    # 16 envs: two batches of the compiled reset of N envs
    state = jax.tree.map(lambda *x: np.concatenate(x), *(jax.device_get(moving.start(seed)) for seed in (1, 2)))
    pos = np.asarray(state.info["obstacle_pos"]).reshape(16, 3, 3)
    radii = np.asarray(state.info["obstacle_radius"])
    vel = np.asarray(state.info["obstacle_vel"]).reshape(16, 3, 3)
    assert float(state.metrics["reset_fallback"].max()) == 0.0
    assert (np.abs(pos) <= cfg.obstacle_region).all()
    assert (radii >= 0.05).all()
    assert (radii <= 0.15).all()
    assert np.ptp(radii) > 0.05
    assert np.all((np.linalg.norm(vel, axis=-1) >= 0.05 - 1e-6) & (np.linalg.norm(vel, axis=-1) <= 0.2 + 1e-6))
    assert len({tuple(np.round(p, 4)) for p in pos.reshape(-1, 3)}) == 48  # every obstacle its own
    target = np.asarray(state.info["target_pos"])
    assert (np.linalg.norm(pos - target[:, None], axis=-1) > radii + cfg.target_radius).all()
    for q, p, r in zip(np.asarray(state.pipeline_state.qpos), pos, radii):
        contacts, distances, _ = obstacle_contacts(obstacles_model(env.robot, r, every_geom=True), q, p)
        assert not contacts
        assert distances.min() > 0


@pytest.mark.parametrize("name", ["ur5e-reach-avoid", "panda-reach-avoid"])
@pytest.mark.parametrize("motion", ["static", "linear"])
def test_several_obstacles_collide_as_in_mujoco(name, motion):
    """Static obstacles against the model's obstacle pairs, moving ones against every robot geom."""
    env = envs.make(name, num_obstacles=3, obstacle_radius_range=(0.03, 0.15), obstacle_motion=motion, substeps=2)
    robot, checked = env.robot, env.checked_geoms
    rng = np.random.default_rng(2)
    qpos = rng.uniform(robot.joint_low, robot.joint_high, size=(120, robot.nq)).astype(np.float32)
    kin = jax.jit(robot.kinematics)(qpos)
    # Three obstacles near random checked geoms, each touching one about a third of the time.
    geoms = rng.choice(checked, size=(len(qpos), 3))
    centers = np.asarray(kin.geom_xpos)[np.arange(len(qpos))[:, None], geoms] + rng.normal(scale=0.2, size=(len(qpos), 3, 3))
    radii = rng.uniform(0.03, 0.15, size=(len(qpos), 3)).astype(np.float32)
    info = {"obstacle_pos": jnp.asarray(centers.reshape(-1, 9), jnp.float32), "obstacle_radius": jnp.asarray(radii)}

    @jax.jit
    @jax.vmap
    def ours(gx, gm, info):
        per_geom = env.per_obstacle(info, lambda c, r: robot.obstacle_distances(gx, gm, c, r, checked))
        return per_geom, env.collision_distances(gx, gm, info)[1]

    per_geom, closest = map(np.asarray, ours(kin.geom_xpos, kin.geom_xmat, info))
    colliding = clear = 0
    model = lambda r: obstacles_model(robot, r, every_geom=motion != "static")  # noqa: E731
    for q, c, r, d, m in zip(qpos, centers.astype(np.float32), radii, per_geom, closest):
        contacts, reference, robot_geoms = obstacle_contacts(model(r), q, c)
        assert list(robot_geoms) == list(checked)
        np.testing.assert_allclose(d, reference, atol=1e-4)  # every (obstacle, geom) signed distance
        np.testing.assert_allclose(m, reference.min(), atol=1e-4)  # the step's check: the closest of all
        for j in range(3):
            for geom, value in zip(checked, d[j]):
                if abs(value) >= BORDERLINE:
                    assert (value < 0) == ((j, int(geom)) in contacts), (q, j, geom, value)
        if abs(m) >= BORDERLINE:
            colliding += m < 0
            clear += m > 0
            assert (m < 0) == bool(contacts)
    assert colliding > 30, colliding
    assert clear > 20, clear


def _crossing_direction(robot, q, point, radii, others, rng, reach=0.2, region=0.6):
    """A direction u such that an obstacle of radius radii[0] at point -+ reach*u is clear of the arm at q, every
    robot geom as for a moving obstacle (CPU MuJoCo, 1 cm margin), and inside the cube; the other obstacles stay at
    `others`."""
    model = obstacles_model(robot, radii, every_geom=True)
    for _ in range(500):
        u = rng.normal(size=3)
        u /= np.linalg.norm(u)
        ends = [point - reach * u, point + reach * u]
        if any(np.abs(e).max() > region - 0.01 for e in ends):
            continue
        if all(obstacle_contacts(model, q, np.vstack([e[None], others]))[1][0].min() > 0.01 for e in ends):
            return u
    return None


def test_moving_obstacles_checked_at_every_substep_as_in_mujoco(moving):
    """An obstacle that crosses a link between the step's first and last physics substep collides:
    clear at substeps 0 and 2 (the step's end), inside a link at substep 1, by our check and MuJoCo's."""
    env, robot = moving.env, moving.env.robot
    dt = env.physics_dt
    state = moving.start(seed=3)
    q0 = np.asarray(state.pipeline_state.qpos)
    info = jax.tree.map(np.array, state.info)
    rng = np.random.default_rng(4)
    crossing = np.arange(N) < N // 2
    expected_end = []
    for e in range(N):
        motion = info["obstacle_motion"]
        radii = info["obstacle_radius"][e].copy()
        radii[0] = 0.05
        others = info["obstacle_pos"][e].reshape(3, 3)[1:]
        motion["velocity"][e, 1:] = 0.0  # the other two stand still (they start clear of the arm)
        gx = np.asarray(state.pipeline_state.geom_xpos)[e]
        inside = [g for g in robot.obstacle_geoms if np.abs(gx[g]).max() < 0.6 - 0.21]
        u = None
        while u is None and inside:
            point = gx[inside.pop(0)]
            u = _crossing_direction(robot, q0[e], point, radii, others, rng)
        assert u is not None, "no link to cross found"
        speed = 0.2 / dt  # 0.2 m per physics step: at substep 1 the obstacle's centre is on the link's
        if crossing[e]:
            motion["center"][e, 0], motion["velocity"][e, 0] = point - 0.2 * u, speed * u
        else:  # control: the same clear start, standing still
            motion["center"][e, 0], motion["velocity"][e, 0] = point - 0.2 * u, 0.0
        info["obstacle_radius"][e] = radii
        ends = [point - 0.2 * u + k * 0.2 * u * crossing[e] for k in range(3)]
        model = obstacles_model(robot, radii, every_geom=True)
        verdicts = [bool(obstacle_contacts(model, q0[e], np.vstack([p[None], others]))[0]) for p in ends]
        assert verdicts == [False, bool(crossing[e]), False], verdicts  # MuJoCo: only substep 1 collides
        expected_end.append(ends[2])
    info = jax.vmap(lambda i: env.task_at(i, 0))(jax.tree.map(jnp.asarray, info))  # positions from the new motions
    after = moving.step(state.replace(info=info), standstill(env))
    np.testing.assert_array_equal(after.metrics["obstacle_collision"], crossing.astype(np.float32))
    np.testing.assert_array_equal(after.metrics["self_collision"], 0.0)
    # The state after the step holds the obstacles where they are at its end (2 substeps).
    np.testing.assert_allclose(np.asarray(after.info["obstacle_pos"]).reshape(N, 3, 3)[:, 0], expected_end, atol=1e-5)


@pytest.mark.parametrize("name, fixed", [("ur5e-reach-avoid", ["base", "shoulder"]),
                                         ("panda-reach-avoid", ["link0", "link1"])])
def test_moving_obstacles_are_checked_against_the_geoms_no_joint_moves(name, fixed):
    """The model's obstacle pairs leave out the base and the first link (no joint moves them, so a static obstacle
    sampled clear of them never touches them); a moving obstacle is checked against every robot geom."""
    static = envs.make(name, num_obstacles=3, substeps=2)
    linear = envs.make(name, num_obstacles=3, obstacle_motion="linear", substeps=2)
    robot = linear.robot
    assert [robot.mj_model.geom(int(g)).name for g in robot.fixed_geoms] == fixed
    assert list(linear.checked_geoms) == list(robot.robot_geoms)
    assert list(static.checked_geoms) == list(robot.obstacle_geoms)


def test_a_moving_obstacle_in_the_base_collides():
    """An obstacle of radius 0.05 whose centre is 0.1 m below the base sphere's (radius 0.075) overlaps it by 2.5 cm:
    a collision when obstacles move; with static ones the base is not checked (the paper's pairs)."""
    env = envs.make("ur5e-reach-avoid", num_obstacles=3, obstacle_radius=0.05, obstacle_motion="linear", substeps=2)
    static = envs.make("ur5e-reach-avoid", num_obstacles=3, obstacle_radius=0.05, substeps=2)
    robot = env.robot
    kin = robot.kinematics(jnp.zeros(robot.nq))
    base = int(robot.mj_model.geom("base").id)
    center = np.asarray(kin.geom_xpos)[base] + np.array([0.0, 0.0, -0.1])
    far = np.array([0.0, 0.0, -0.5])  # the other two, below the mounting plane
    info = {"obstacle_pos": jnp.asarray(np.concatenate([center, far, far]), jnp.float32)}
    by_hand = 0.1 - 0.075 - 0.05  # centre 0.1 m from the base sphere's, radii from assets/ur5e.xml and the config
    np.testing.assert_allclose(env.collision_distances(kin.geom_xpos, kin.geom_xmat, info)[1], by_hand, atol=1e-5)
    assert static.collision_distances(kin.geom_xpos, kin.geom_xmat, info)[1] > 0


def _moving_arm(moving):
    """The moving-obstacle envs after one step of random actions (every arm moving) and their info with noise keys."""
    env = moving.env
    actions = jax.random.uniform(jax.random.PRNGKey(3), (N, env.action_size), minval=-1.0, maxval=1.0)
    state = moving.step(moving.start(seed=6), actions)
    return state, {**state.info, "noise_key": jax.random.split(jax.random.PRNGKey(4), N)}


@pytest.mark.parametrize("speed_up", [1.0, 30.0])
def test_the_moving_look_ahead_moves_the_arm_on_at_its_joint_velocities(moving, speed_up):
    """link_obstacle_ahead_moving: per horizon and link, the distance to the nearest obstacle's surface with the
    obstacles moved on at their velocities and the arm at its joint velocities; the links' origins there from CPU
    MuJoCo's kinematics at qpos + horizon * qvel clipped to the joint ranges, after a step of random actions (and
    with those velocities 30 times faster, which takes joints past their limits)."""
    import mujoco

    env, robot = moving.env, moving.env.robot
    state, _ = _moving_arm(moving)
    data = state.pipeline_state.replace(qvel=state.pipeline_state.qvel * speed_up)
    assert np.min(np.linalg.norm(np.asarray(data.qvel), axis=-1)) > 0.1  # every arm moving
    ahead = np.asarray(jax.vmap(lambda d, i: env.link_distances_ahead(d, d.xpos, i, arm_moving=True))(
        data, state.info))
    pos, radii = np.asarray(state.info["obstacle_pos"]), np.asarray(state.info["obstacle_radius"])
    vel = np.asarray(state.info["obstacle_vel"])
    nlinks, model = len(robot.link_bodies), robot.mj_model
    reference, past_a_limit = mujoco.MjData(model), False
    for i in range(N):
        for k, horizon in enumerate(env.config.obstacle_lookahead):
            moved_on = np.asarray(data.qpos[i], np.float64) + horizon * np.asarray(data.qvel[i])
            past_a_limit |= bool(np.any((moved_on < robot.joint_low) | (moved_on > robot.joint_high)))
            reference.qpos[:robot.nq] = np.clip(moved_on, robot.joint_low, robot.joint_high)  # stopped at a limit
            mujoco.mj_kinematics(model, reference)
            links = reference.xpos[robot.link_bodies]
            centres = (pos[i] + horizon * vel[i]).reshape(3, 1, 3)
            expected = (np.linalg.norm(links[None] - centres, axis=-1) - radii[i][:, None]).min(axis=0)
            np.testing.assert_allclose(ahead[i, k * nlinks:(k + 1) * nlinks], expected, atol=1e-4)
    assert past_a_limit or speed_up == 1.0  # the fast case exercises the stop at the limits


def test_the_moving_look_ahead_measures_surfaces_at_the_moved_pose(moving):
    """With link_distance="surface" the prediction measures the links' capsules where the arm will be: the env's own
    surface distance at the geom poses CPU MuJoCo's kinematics gives for the moved-on angles."""
    import mujoco

    env = envs.make("ur5e-reach-avoid", **dict(MOVING, link_distance="surface"))
    robot, model = env.robot, env.robot.mj_model
    state, _ = _moving_arm(moving)
    data, reference = state.pipeline_state, mujoco.MjData(model)
    ahead = np.asarray(jax.vmap(lambda d, i: env.link_distances_ahead(d, d.xpos, i, arm_moving=True))(
        data, state.info))
    nlinks, horizon = len(robot.link_bodies), env.config.obstacle_lookahead[-1]
    for i in range(N):
        one = jax.tree.map(lambda x: x[i], data)
        reference.qpos[:robot.nq] = np.clip(np.asarray(one.qpos) + horizon * np.asarray(one.qvel), robot.joint_low,
                                            robot.joint_high)
        mujoco.mj_kinematics(model, reference)
        posed = one.replace(geom_xpos=jnp.asarray(reference.geom_xpos, jnp.float32),
                            geom_xmat=jnp.asarray(reference.geom_xmat.reshape(-1, 3, 3), jnp.float32))
        info = jax.tree.map(lambda x: x[i], state.info)
        moved = {**info, "obstacle_pos": info["obstacle_pos"] + horizon * info["obstacle_vel"]}
        expected = np.min(np.asarray(env.link_distances(posed, jnp.asarray(reference.xpos, jnp.float32), moved)), axis=0)
        np.testing.assert_allclose(ahead[i, nlinks:], expected, atol=1e-4)


def test_the_moving_look_ahead_differs_from_the_arm_held_still(moving):
    """With the arm moving, the prediction is not link_obstacle_ahead's (which holds the arm still)."""
    env = moving.env
    state, _ = _moving_arm(moving)
    data = state.pipeline_state
    still = jax.vmap(env.link_distances_ahead)(data, data.xpos, state.info)
    moving_on = jax.vmap(lambda d, i: env.link_distances_ahead(d, d.xpos, i, arm_moving=True))(data, state.info)
    assert float(jnp.max(jnp.abs(moving_on - still))) > 0.05


def test_the_moving_look_ahead_is_the_observation_part_of_that_name(moving):
    """The part `link_obstacle_ahead_moving` of an env that observes it, on a moving arm's state, is that prediction
    (two horizons x the links)."""
    env = envs.make("ur5e-reach-avoid", **dict(MOVING, observation=MOVING["observation"] + ("link_obstacle_ahead_moving",)))
    state, _ = _moving_arm(moving)
    data, ee_site = state.pipeline_state, env.robot.ee_site
    obs = jax.vmap(lambda d, i: env.observation(d, d.xpos, d.site_xpos[ee_site], i))(data, state.info)
    expected = jax.vmap(lambda d, i: env.link_distances_ahead(d, d.xpos, i, arm_moving=True))(data, state.info)
    np.testing.assert_allclose(split_obs(env, obs)["link_obstacle_ahead_moving"], expected, atol=1e-6)


@pytest.mark.parametrize("model", ["angles", "encoders"])
def test_the_moving_look_ahead_sees_joint_noise_only_through_encoders(moving, model):
    """Joint noise of 0.05 rad: under `angles` the prediction is the noiseless one (the noise reaches joint_pos
    only); under `encoders` it comes from the noisy angles, centimetres away."""
    state, info = _moving_arm(moving)
    data = state.pipeline_state
    env = envs.make("ur5e-reach-avoid", **dict(MOVING, joint_noise_std=0.05, joint_noise_model=model,
                                                observation=("joint_pos", "link_obstacle_ahead_moving")))
    obs = jax.vmap(lambda d, i: env.observation(d, d.xpos, d.site_xpos[env.robot.ee_site], i))(data, info)
    parts = split_obs(env, obs)
    exact = np.asarray(jax.vmap(lambda d, i: env.link_distances_ahead(d, d.xpos, i, arm_moving=True))(data, state.info))
    assert np.max(np.abs(parts["joint_pos"] - np.asarray(data.qpos))) > 0.01  # the noise is on
    deviation = np.max(np.abs(parts["link_obstacle_ahead_moving"] - exact))
    assert (deviation < 1e-6) if model == "angles" else (deviation > 1e-3)


def test_observations_and_penalty_of_several_moving_obstacles(moving):
    env, cfg, robot = moving.env, moving.env.config, moving.env.robot
    state = moving.start(seed=5)
    nlinks = len(robot.link_bodies)
    assert env.observation_size == 6 + 3 + 3 + 9 + 9 + 3 + 9 + nlinks + 2 * nlinks  # 2 look-ahead horizons
    after = moving.step(state, standstill(env))
    for s in (state, after):
        parts = split_obs(env, s.obs)
        pos = np.asarray(s.info["obstacle_pos"])
        radii = np.asarray(s.info["obstacle_radius"])
        np.testing.assert_array_equal(parts["joint_pos"], s.pipeline_state.qpos)  # noise is off by default
        np.testing.assert_array_equal(parts["obstacle_pos"], pos)
        np.testing.assert_array_equal(parts["obstacle_size"], np.repeat(radii, 3, axis=-1))
        np.testing.assert_array_equal(parts["obstacle_radius"], radii)
        np.testing.assert_array_equal(parts["obstacle_vel"], s.info["obstacle_vel"])
        # Per link, the distance to the nearest obstacle's surface (paper's d_i: from the link's origin).
        links = np.asarray(s.pipeline_state.xpos)[:, robot.link_bodies]
        d = np.linalg.norm(links[:, None] - pos.reshape(N, 3, 1, 3), axis=-1) - radii[..., None]
        np.testing.assert_allclose(parts["link_obstacle_dist"], d.min(axis=1), atol=1e-5)
        # Looking ahead: each obstacle moved on by its velocity times 0.5 s, then 2 s, in a straight line.
        vel = np.asarray(s.info["obstacle_vel"]).reshape(N, 3, 1, 3)
        for k, horizon in enumerate((0.5, 2.0)):
            moved = np.linalg.norm(links[:, None] - (pos.reshape(N, 3, 1, 3) + horizon * vel), axis=-1) - radii[..., None]
            np.testing.assert_allclose(parts["link_obstacle_ahead"][:, k * nlinks:(k + 1) * nlinks], moved.min(axis=1),
                                       atol=1e-5)
    # Obstacles of 0.05-0.2 m/s moved on for 2 s: the prediction differs from the present by centimetres or more.
    assert np.max(np.abs(parts["link_obstacle_ahead"][:, nlinks:] - parts["link_obstacle_dist"])) > 0.05
    # Radii and velocities vary between episodes here, so no part is constant (what evaluation checks use).
    assert cfg.constant_observations() == {}
    assert np.ptp(parts["obstacle_radius"]) > 0.01
    assert np.ptp(parts["obstacle_vel"]) > 0.01
    # The obstacles after one step: the closed form at 2 physics steps, a straight line from the centre here.
    motion = jax.tree.map(np.asarray, state.info["obstacle_motion"])
    free = motion["center"] + motion["velocity"] * 2 * env.physics_dt
    np.testing.assert_allclose(np.asarray(after.info["obstacle_pos"]).reshape(N, 3, 3),
                               reflect_by_hand(free, -cfg.obstacle_region, cfg.obstacle_region), atol=1e-6)
    assert not np.allclose(after.info["obstacle_pos"], state.info["obstacle_pos"])
    # Penalty, eq. (3) summed over every (link, obstacle) pair: two obstacles 0.05 m and 0.02 m above links 1
    # and 2, the third on link 2 as well, farther (0.08 m).
    one = jax.tree.map(lambda x: x[0], state)
    data = one.pipeline_state
    links = np.asarray(data.xpos)[robot.link_bodies]
    radii = np.array([0.1, 0.06, 0.12], np.float32)
    centers = links[[1, 2, 2]] + np.array([[0, 0, 0.1 + 0.05], [0, 0, 0.06 + 0.02], [0, 0, -0.12 - 0.08]])
    info = {**one.info, "obstacle_pos": jnp.asarray(centers.ravel(), jnp.float32), "obstacle_radius": jnp.asarray(radii)}
    d = np.linalg.norm(links[None] - centers[:, None], axis=-1) - radii[:, None]
    penalty = cfg.w_obst * np.maximum(0, 1 - d / cfg.obstacle_tau).sum()
    assert penalty > cfg.w_obst * (0.5 + 0.8 + 0.2) - 1e-5
    reward = env.reward(data, jnp.float32(0.3), jnp.float32(0.0), info)
    np.testing.assert_allclose(float(reward), (2 * robot.reach - 0.3) - penalty, atol=1e-5)


# ------------------------------------------------------------------------------------------------
# Noise and latency


def test_noise_is_seeded_fresh_each_step_and_only_in_the_observation(sensing):
    env, robot = sensing.env, sensing.env.robot
    state = sensing.start(seed=6, n=SENSING_N)
    again = sensing.start(seed=6, n=SENSING_N)
    other = sensing.start(seed=7, n=SENSING_N)
    np.testing.assert_array_equal(state.obs, again.obs)  # same key, same noise

    def noise(s):
        parts = split_obs(env, s.obs)
        return (parts["joint_pos"] - np.asarray(s.pipeline_state.qpos),
                parts["obstacle_pos"] - np.asarray(s.info["obstacle_pos"]))

    joint, obstacle = noise(state)
    assert 0.007 < joint.std() < 0.013
    assert abs(joint.mean()) < 0.005
    assert 0.013 < obstacle.std() < 0.027
    assert abs(obstacle.mean()) < 0.01
    assert not np.allclose(noise(other)[0], joint)  # another key, other noise
    # The link distances are those of the perceived (noisy) obstacle; the state keeps the true one.
    parts = split_obs(env, state.obs)
    links = np.asarray(state.pipeline_state.xpos)[:, robot.link_bodies]
    d = np.linalg.norm(links - parts["obstacle_pos"][:, None], axis=-1) - env.config.obstacle_radius
    np.testing.assert_allclose(parts["link_obstacle_dist"], d, atol=1e-5)
    np.testing.assert_allclose(parts["link_obstacle_ahead"], np.tile(d, 2), atol=1e-5)  # static: both horizons alike
    actions = jax.random.uniform(jax.random.PRNGKey(8), (SENSING_N, env.action_size), minval=-1, maxval=1)
    after = sensing.step(state, actions)
    np.testing.assert_array_equal(after.obs, sensing.step(again, actions).obs)  # reproducible through a step
    np.testing.assert_array_equal(after.info["obstacle_pos"], state.info["obstacle_pos"])  # truth untouched
    step_joint, step_obstacle = noise(after)
    assert 0.007 < step_joint.std() < 0.013
    assert not np.allclose(step_joint, joint)
    assert not np.allclose(step_obstacle, obstacle)  # fresh every step


ENCODER_PARTS = ("joint_pos", "ee_pos", "target_pos", "ee_to_target", "self_dist", "link_pos", "obstacle_pos",
                 "link_obstacle_dist", "link_obstacle_ahead")


def test_encoder_noise_reaches_every_part_computed_from_the_joints():
    """joint_noise_model="encoders": ee_pos, ee_to_target, self_dist, link_pos, link_obstacle_dist and _ahead are those
    of the noisy angles that joint_pos reports, by CPU MuJoCo's kinematics at those angles; the state keeps the true
    pose. With "angles" (the default) the same key gives the same noisy angles and the true end effector. Reset only:
    it compiles no physics."""
    options = dict(joint_noise_std=0.05, observation=ENCODER_PARTS, substeps=2)
    keys = jax.random.split(jax.random.PRNGKey(11), N)
    encoders = envs.make("ur5e-reach-avoid", joint_noise_model="encoders", **options)
    angles = envs.make("ur5e-reach-avoid", **options)
    state = jax.jit(jax.vmap(encoders.reset))(keys)
    plain = jax.jit(jax.vmap(angles.reset))(keys)
    robot, model = encoders.robot, encoders.robot.mj_model
    parts, plain_parts = split_obs(encoders, state.obs), split_obs(angles, plain.obs)
    np.testing.assert_array_equal(parts["joint_pos"], plain_parts["joint_pos"])  # the same noise
    true_q = np.asarray(state.pipeline_state.qpos)
    assert 0.03 < (parts["joint_pos"] - true_q).std() < 0.07
    radius = encoders.config.obstacle_radius
    for i in range(N):
        q = parts["joint_pos"][i].astype(np.float64)
        ee = ee_position(model, q)
        np.testing.assert_allclose(parts["ee_pos"][i], ee, atol=2e-5)
        np.testing.assert_allclose(parts["ee_to_target"][i], np.asarray(state.info["target_pos"][i]) - ee, atol=2e-5)
        true_ee = ee_position(model, true_q[i].astype(np.float64))
        np.testing.assert_allclose(plain_parts["ee_pos"][i], true_ee, atol=2e-5)
        np.testing.assert_allclose(state.pipeline_state.site_xpos[i, robot.ee_site], true_ee, atol=2e-5)  # state: true
        assert np.linalg.norm(parts["ee_pos"][i] - plain_parts["ee_pos"][i]) > 1e-3  # 0.05 rad moves it mm to cm
        geom_xpos, geom_xmat = geom_poses(model, q)
        np.testing.assert_allclose(parts["self_dist"][i], robot.self_distances(geom_xpos, geom_xmat), atol=1e-4)
        data = mujoco.MjData(model)
        data.qpos[:] = q
        mujoco.mj_kinematics(model, data)
        links = data.xpos[robot.link_bodies]
        np.testing.assert_allclose(parts["link_pos"][i].reshape(-1, 3), links, atol=2e-5)
        d = np.linalg.norm(links - parts["obstacle_pos"][i], axis=-1) - radius  # the paper's d_i, from link origins
        np.testing.assert_allclose(parts["link_obstacle_dist"][i], d, atol=2e-5)
        np.testing.assert_allclose(parts["link_obstacle_ahead"][i], np.tile(d, 2), atol=2e-5)  # static obstacle


def test_action_latency_applies_the_previous_action(sensing):
    env, robot = sensing.env, sensing.env.robot
    scale, low, high = env.config.action_scale, robot.joint_low, robot.joint_high
    s0 = sensing.start(seed=9, n=SENSING_N)
    a1 = np.asarray(jax.random.uniform(jax.random.PRNGKey(10), (SENSING_N, env.action_size), minval=-1, maxval=1))
    a2 = -a1
    np.testing.assert_array_equal(s0.info["prev_action"], 0.0)  # relative control: the first step holds the pose
    s1 = sensing.step(s0, jnp.asarray(a1))
    np.testing.assert_array_equal(s1.pipeline_state.ctrl, s0.pipeline_state.qpos)  # q0 + 0.2 * 0
    np.testing.assert_array_equal(s1.info["prev_action"], a1)
    s2 = sensing.step(s1, jnp.asarray(a2))
    q1 = np.asarray(s1.pipeline_state.qpos)
    np.testing.assert_allclose(s2.pipeline_state.ctrl, np.clip(q1 + scale * a1, low, high), atol=1e-6)  # a1, not a2
    assert np.abs(np.asarray(s2.pipeline_state.ctrl) - np.clip(q1 + scale * a2, low, high)).max() > 0.1
    # Absolute control: the held action maps back onto the pose, so the first step holds it too.
    absolute = envs.make("ur5e-reach", action="absolute", action_latency=1, substeps=2)
    q = jnp.asarray(np.asarray(s0.pipeline_state.qpos)[0])
    np.testing.assert_allclose(absolute.action_to_ctrl(absolute.hold_action(q), jnp.zeros(6)), q, atol=1e-5)
    first = jax.jit(absolute.reset)(jax.random.PRNGKey(11))
    np.testing.assert_allclose(absolute.action_to_ctrl(first.info["prev_action"], jnp.zeros(6)),
                               first.pipeline_state.qpos, atol=1e-5)


def test_latency_starts_each_auto_reset_episode_by_holding_its_own_pose():
    """In the training stack (episode limit 2, auto-reset), the step after an auto-reset applies the new
    episode's hold action, not the last action of the episode that ended."""
    env = envs.make("ur5e-reach-avoid", **SENSING)
    stack = envs.wrap(env, episode_length=2)
    reset, step = jax.jit(stack.reset), jax.jit(stack.step)
    a = 0.5 * jax.random.uniform(jax.random.PRNGKey(13), (N, env.action_size), minval=-1, maxval=1)
    s1 = step(reset(jax.random.split(jax.random.PRNGKey(12), N)), a)
    s2 = step(s1, -a)  # the time limit ends every episode here: the state is the next episode's start
    s3 = step(s2, a)
    ok = (np.asarray(s1.done) == 0) & (np.asarray(s2.info["truncation"]) == 1) & (np.asarray(s3.done) == 0)
    assert ok.sum() >= N // 2  # episodes that ended by the time limit and whose next step did not end
    np.testing.assert_array_equal(np.asarray(s2.info["prev_action"])[ok], 0.0)
    q_new = np.asarray(s2.pipeline_state.qpos)[ok]
    np.testing.assert_array_equal(np.asarray(s3.pipeline_state.ctrl)[ok], q_new)  # q + 0.2 * 0: holds the new pose
    stale = np.clip(q_new - env.config.action_scale * np.asarray(a)[ok], env.robot.joint_low, env.robot.joint_high)
    assert np.abs(np.asarray(s3.pipeline_state.ctrl)[ok] - stale).max(axis=1).min() > 0.01  # not the old episode's -a


def test_render_draws_every_obstacle_at_its_radius():
    from envs import render

    env = envs.make("ur5e-reach-avoid", num_obstacles=3, obstacle_radius_range=(0.05, 0.2), substeps=2)
    away = np.tile([0.0, 0.0, -5.0], (3, 1))
    with render.Scene(env, 160, 120) as scene:
        q, target = np.zeros(6), np.array([0.3, 0.3, 0.5])
        empty = scene.draw(q, target, away.ravel()).astype(int)
        for j in range(3):
            shown = away.copy()
            shown[j] = [0.3, -0.4, 0.3]
            small = scene.draw(q, target, shown.ravel(), np.full(3, 0.05)).astype(int)
            assert np.abs(small - empty).sum(-1).astype(bool).sum() > 20, f"obstacle {j} not drawn"
            large = scene.draw(q, target, shown.ravel(), np.full(3, 0.2)).astype(int)
            assert np.abs(large - empty).sum(-1).astype(bool).sum() > 4 * np.abs(small - empty).sum(-1).astype(bool).sum()


def test_the_throughput_variants_add_both_predictions_to_the_moving_setting():
    """benchmarks.env_throughput's last variant observes the 3-moving setting plus both look-aheads: 2 parts x 2
    horizons x the links more numbers."""
    from benchmarks.env_throughput import VARIANTS

    sizes = {v: envs.make("ur5e-reach-avoid", **VARIANTS[v]).observation_size
             for v in ("3-moving", "3-moving-ahead-moving")}
    nlinks = len(envs.make("ur5e-reach-avoid").robot.link_bodies)
    assert sizes["3-moving-ahead-moving"] - sizes["3-moving"] == 2 * 2 * nlinks
