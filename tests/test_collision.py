"""Analytic capsule/sphere distances against brute force, hand-computed cases and MuJoCo's own
collision detection (`mj_collision` on the same explicit pairs, CPU MuJoCo)."""

import jax
import jax.numpy as jnp
import numpy as np
import pytest

from envs import collision
from envs.robots import ROBOTS
from mujoco_reference import colliding_pairs, contact_model, geom_poses

BORDERLINE = 1e-4  # configurations this close to touching are skipped (float32 vs float64)


def test_segment_distance_against_brute_force():
    rng = np.random.default_rng(0)
    n_grid = 401
    grid = np.linspace(0.0, 1.0, n_grid)
    for trial in range(300):
        p0, p1, q0, q1 = rng.normal(size=(4, 3))
        if trial % 5 == 1:
            p1 = p0.copy()  # point vs segment
        elif trial % 5 == 2:
            q1 = q0.copy()  # segment vs point
        elif trial % 5 == 3:
            p1, q1 = p0.copy(), q0.copy()  # point vs point
        elif trial % 5 == 4:
            q1 = q0 + (p1 - p0) * rng.uniform(-2, 2)  # parallel segments
        points_p = p0 + grid[:, None] * (p1 - p0)
        points_q = q0 + grid[:, None] * (q1 - q0)
        brute = np.min(np.linalg.norm(points_p[:, None] - points_q[None], axis=-1))
        analytic = float(collision.segment_distance(*map(jnp.asarray, (p0, p1, q0, q1))))
        # The grid misses the true minimum by at most half a grid step along each segment.
        bound = (np.linalg.norm(p1 - p0) + np.linalg.norm(q1 - q0)) / (2 * (n_grid - 1)) + 1e-5
        assert -1e-5 <= brute - analytic <= bound, (trial, brute, analytic)


def test_hand_computed_distances():
    seg = lambda a, b: (jnp.array(a, float), jnp.array(b, float))
    # Crossing segments 0.3 apart in z.
    assert np.isclose(collision.segment_distance(*seg([-1, 0, 0], [1, 0, 0]), *seg([0, -1, 0.3], [0, 1, 0.3])), 0.3, atol=1e-5)
    # Parallel, overlapping in x, 0.2 apart in y.
    assert np.isclose(collision.segment_distance(*seg([0, 0, 0], [1, 0, 0]), *seg([0.5, 0.2, 0], [2, 0.2, 0])), 0.2, atol=1e-5)
    # Collinear, end to end with a 0.5 gap.
    assert np.isclose(collision.segment_distance(*seg([0, 0, 0], [1, 0, 0]), *seg([1.5, 0, 0], [3, 0, 0])), 0.5, atol=1e-5)
    # Point beyond a segment's end: distance to the end point (3-4-5 triangle).
    assert np.isclose(collision.point_segment_distance(jnp.array([4.0, 4.0, 0.0]), *seg([0, 0, 0], [1, 0, 0])), 5.0, atol=1e-5)
    # Two capsules (radius 0.05 and 0.1) whose axes are 0.2 apart: signed distance 0.05.
    xmat = jnp.stack([jnp.eye(3), jnp.eye(3)])
    d = collision.pair_distances(jnp.array([[0, 0, 0], [0.2, 0, 0.0]]), xmat, jnp.array([0.05, 0.1]),
                                 jnp.array([0.3, 0.1]), np.array([0]), np.array([1]))
    assert np.isclose(d[0], 0.05, atol=1e-5)
    # A sphere of radius 0.1 touching a capsule's end cap from above overlaps by 0.02.
    d = collision.sphere_distances(jnp.array([0, 0, 0.3 + 0.05 + 0.08]), 0.1, jnp.zeros((1, 3)), xmat[:1],
                                   jnp.array([0.05]), jnp.array([0.3]), np.array([0]))
    assert np.isclose(d[0], -0.02, atol=1e-5)


@pytest.fixture(scope="module", params=sorted(ROBOTS))
def robot(request):
    return ROBOTS[request.param]()


@pytest.fixture(scope="module")
def kinematics(robot):
    return jax.jit(robot.kinematics)


def _sample_configs(robot, n, seed):
    rng = np.random.default_rng(seed)
    return rng.uniform(robot.joint_low, robot.joint_high, size=(n, robot.nq)).astype(np.float32)


def test_kinematics_match_cpu_mujoco(robot, kinematics):
    model = contact_model(robot)
    qpos = _sample_configs(robot, 5, seed=1)
    kin = kinematics(qpos)
    for q, gx, gm in zip(qpos, np.asarray(kin.geom_xpos), np.asarray(kin.geom_xmat)):
        ref_x, ref_m = geom_poses(model, q)
        np.testing.assert_allclose(gx, ref_x, atol=2e-5)
        np.testing.assert_allclose(gm, ref_m, atol=2e-5)


def test_self_collision_agrees_with_mj_collision(robot, kinematics):
    model = contact_model(robot)
    qpos = _sample_configs(robot, 600, seed=2)
    kin = kinematics(qpos)
    dist = np.asarray(robot.self_distances(kin.geom_xpos, kin.geom_xmat))
    pairs = [tuple(sorted(map(int, p))) for p in robot.self_pairs]
    checked = colliding = 0
    for q, d in zip(qpos, dist):
        reference = colliding_pairs(model, q)
        for pair, value in zip(pairs, d):
            if abs(value) < BORDERLINE:
                continue
            checked += 1
            colliding += value < 0
            assert (value < 0) == (pair in reference), (q, pair, value)
        # MuJoCo reports nothing outside the pair list (all geoms have contype = conaffinity = 0).
        assert reference <= set(pairs)
    assert checked > 0.99 * dist.size
    assert colliding > 20, "the sample should contain self-collisions to compare"


def test_obstacle_collision_agrees_with_mj_collision(robot, kinematics):
    radius = 0.1
    model = contact_model(robot, obstacle_radius=radius)
    obstacle_geom = model.geom("obstacle").id
    rng = np.random.default_rng(3)
    qpos = _sample_configs(robot, 200, seed=4)
    kin = kinematics(qpos)
    # Obstacles near a random robot geom, so that about half of them touch it.
    geoms = rng.choice(robot.obstacle_geoms, size=len(qpos))
    centers = np.asarray(kin.geom_xpos)[np.arange(len(qpos)), geoms] + rng.normal(scale=0.12, size=(len(qpos), 3))
    dist = np.asarray(robot.obstacle_distances(kin.geom_xpos, kin.geom_xmat, jnp.asarray(centers, jnp.float32), radius))
    colliding = 0
    for q, c, d in zip(qpos, centers, dist):
        reference = colliding_pairs(model, q, obstacle_pos=c)
        for geom, value in zip(robot.obstacle_geoms, d):
            if abs(value) < BORDERLINE:
                continue
            colliding += value < 0
            assert (value < 0) == (tuple(sorted((int(geom), obstacle_geom))) in reference), (q, c, geom, value)
    assert colliding > 50


def test_obstacle_on_each_link_is_detected(robot, kinematics):
    """An obstacle centred on any collision-checked geom collides, by our check and MuJoCo's."""
    model = contact_model(robot, obstacle_radius=0.05)
    q = _sample_configs(robot, 1, seed=5)[0]
    kin = kinematics(q[None])
    for geom in robot.obstacle_geoms:
        center = np.asarray(kin.geom_xpos)[0, geom]
        ours = robot.obstacle_distances(kin.geom_xpos[0], kin.geom_xmat[0], jnp.asarray(center), 0.05)
        assert float(ours[list(robot.obstacle_geoms).index(geom)]) < 0
        assert (int(min(geom, model.geom("obstacle").id)), int(max(geom, model.geom("obstacle").id))) in \
            colliding_pairs(model, q, obstacle_pos=center)
