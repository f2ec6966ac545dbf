"""Robot models in assets/: structure, speeds, collision pairs (CPU MuJoCo; a few seconds in all).

Expected numbers are derived by hand from the published kinematics and limits (see assets/README.md),
not read back from the models.
"""
from __future__ import annotations

import pathlib

import mujoco
import numpy as np
import pytest

ASSETS = pathlib.Path(__file__).resolve().parents[1] / "assets"
PI = np.pi
TWO_PI = 2 * np.pi

SPEC = {
    "ur5e": dict(
        joints=["shoulder_pan_joint", "shoulder_lift_joint", "elbow_joint",
                "wrist_1_joint", "wrist_2_joint", "wrist_3_joint"],
        # Menagerie: +-2pi on every joint except the elbow (+-pi)
        ranges=[(-TWO_PI, TWO_PI)] * 2 + [(-PI, PI)] + [(-TWO_PI, TWO_PI)] * 3,
        vmax=[PI] * 6,                                   # UR5e manual: 180 deg/s
        torque=[150, 150, 150, 28, 28, 28],
        kp=[2000] * 3 + [500] * 3, kv=[400] * 3 + [100] * 3,
        integrator=mujoco.mjtIntegrator.mjINT_IMPLICITFAST,
        geoms=["base", "shoulder", "upper_arm_a", "upper_arm_b", "forearm_a", "forearm_b",
               "wrist_1", "wrist_2_a", "wrist_2_b", "wrist_3"],
        not_near_obstacle={"base", "shoulder"},           # static / spinning about its own axis
        shoulder=(0.0, 0.0, 0.163),
        # qpos = 0: arm stretched along -x; offsets 0.138 - 0.131 + 0.127 (+ 0.1 flange) along -y
        ee_at_zero=(-(0.425 + 0.392), -(0.138 - 0.131 + 0.127 + 0.100), 0.163 - 0.100),
    ),
    "panda": dict(
        joints=[f"joint{i}" for i in range(1, 8)],
        ranges=[(-2.8973, 2.8973), (-1.7628, 1.7628), (-2.8973, 2.8973), (-3.0718, -0.0698),
                (-2.8973, 2.8973), (-0.0175, 3.7525), (-2.8973, 2.8973)],
        vmax=[2.175] * 4 + [2.61] * 3,
        torque=[87] * 4 + [12] * 3,
        kp=[1000, 1000, 750, 750, 300, 300, 300], kv=[20, 20, 4, 4, 2, 2, 2],
        integrator=mujoco.mjtIntegrator.mjINT_EULER,
        geoms=["link0", "link1", "link2", "link3", "link4", "link5_a", "link5_b", "link6",
               "link7_a", "link7_b", "hand", "fingers"],
        not_near_obstacle={"link0", "link1"},
        shoulder=(0.0, 0.0, 0.333),
        # qpos = 0: straight up, flange offset 0.088 along +x, hand (0.107) and fingertips (0.1) down
        ee_at_zero=(0.088, 0.0, 0.333 + 0.316 + 0.384 - 0.107 - 0.100),
    ),
}
ROBOTS = sorted(SPEC)


def load(robot: str) -> mujoco.MjModel:
    return mujoco.MjModel.from_xml_path(str(ASSETS / f"{robot}.xml"))


def with_contacts(robot: str) -> mujoco.MjModel:
    """The model with MuJoCo's collision detection switched on: only the explicit pairs can collide."""
    m = load(robot)
    m.opt.disableflags &= ~int(mujoco.mjtDisableBit.mjDSBL_CONTACT)
    return m


def pair_names(m) -> list[tuple[str, str]]:
    return [(m.geom(m.pair_geom1[k]).name, m.geom(m.pair_geom2[k]).name) for k in range(m.npair)]


def contacts(m, d, q) -> dict[frozenset, float]:
    """Deepest signed distance per touching pair at configuration q."""
    d.qpos[:] = q
    mujoco.mj_kinematics(m, d)
    mujoco.mj_collision(m, d)
    out = {}
    for c in range(d.ncon):
        key = frozenset(m.geom(g).name for g in d.contact.geom[c])
        out[key] = min(out.get(key, 0.0), float(d.contact.dist[c]))
    return out


@pytest.fixture(scope="module", params=ROBOTS)
def robot(request):
    return request.param


# ---------------------------------------------------------------------------------------------- loading
def test_loads_in_mujoco_and_mjx(robot):
    from mujoco import mjx
    m = load(robot)
    mx = mjx.put_model(m)
    assert mx.nq == len(SPEC[robot]["joints"])


def test_options(robot):
    o = load(robot).opt
    assert o.timestep == 0.002
    assert o.solver == mujoco.mjtSolver.mjSOL_NEWTON
    assert (o.iterations, o.ls_iterations) == (1, 6)
    assert o.jacobian == mujoco.mjtJacobian.mjJAC_DENSE
    assert o.integrator == SPEC[robot]["integrator"]
    assert o.disableflags & mujoco.mjtDisableBit.mjDSBL_CONTACT


def test_geometry_is_capsules_and_spheres(robot):
    m = load(robot)
    assert m.nmesh == 0
    assert m.nhfield == 0
    allowed = {mujoco.mjtGeom.mjGEOM_CAPSULE, mujoco.mjtGeom.mjGEOM_SPHERE}
    assert {mujoco.mjtGeom(t) for t in m.geom_type} <= allowed
    assert not m.geom_contype.any()
    assert not m.geom_conaffinity.any()
    names = [m.geom(g).name for g in range(m.ngeom)]
    assert sorted(names) == sorted(SPEC[robot]["geoms"] + ["target", "obstacle"])
    # every body of the arm carries geometry, and the robot geoms are visible (group 2)
    for b in range(1, m.nbody):
        if m.body_mocapid[b] < 0:
            assert m.body_geomnum[b] >= 1, m.body(b).name
    for n in SPEC[robot]["geoms"]:
        assert m.geom(n).group[0] == 2


def test_joints_and_actuators(robot):
    m, s = load(robot), SPEC[robot]
    n = len(s["joints"])
    assert (m.njnt, m.nq, m.nv, m.nu) == (n, n, n, n)
    assert [m.joint(j).name for j in range(n)] == s["joints"]
    assert all(t == mujoco.mjtJoint.mjJNT_HINGE for t in m.jnt_type)
    np.testing.assert_allclose(m.jnt_range, s["ranges"], atol=1e-5)
    np.testing.assert_array_equal(m.actuator_trnid[:, 0], np.arange(n))    # one per joint, in order
    np.testing.assert_allclose(m.actuator_gainprm[:, 0], s["kp"])
    np.testing.assert_allclose(m.actuator_biasprm[:, :3], np.c_[np.zeros(n), -np.array(s["kp"]),
                                                                -np.array(s["kv"])])
    np.testing.assert_allclose(m.actuator_ctrlrange, m.jnt_range, atol=1e-5)
    np.testing.assert_allclose(m.actuator_forcerange, np.c_[-np.array(s["torque"]), s["torque"]])
    assert m.actuator_forcelimited.all()
    assert m.actuator_ctrllimited.all()
    assert (m.dof_damping > 0).all()


def test_frames_ee_site_and_shoulder(robot):
    m, s = load(robot), SPEC[robot]
    d = mujoco.MjData(m)
    mujoco.mj_kinematics(m, d)                     # qpos = 0
    np.testing.assert_allclose(d.site("ee").xpos, s["ee_at_zero"], atol=1e-6)
    np.testing.assert_allclose(d.xpos[m.body("target").id], [0, 0, -5])
    # joint 1 is the vertical axis through the origin; joint 2's axis meets it at the shoulder point
    for q1 in (0.3, -0.7):
        d.qpos[:] = 0
        d.qpos[0] = q1
        mujoco.mj_kinematics(m, d)
        mujoco.mj_comPos(m, d)
        np.testing.assert_allclose(d.xaxis[0], [0, 0, 1], atol=1e-9)
        p, a = d.xanchor[1], d.xaxis[1]
        to_shoulder = np.array(s["shoulder"]) - p
        assert np.linalg.norm(np.cross(to_shoulder, a)) < 1e-6


def test_markers(robot):
    m = load(robot)
    for name, radius, colour in (("target", 0.01, 1), ("obstacle", 0.1, 0)):
        g = m.geom(name)
        assert g.type[0] == mujoco.mjtGeom.mjGEOM_SPHERE
        assert g.size[0] == radius
        assert m.body_mocapid[g.bodyid[0]] >= 0
        assert np.argmax(g.rgba[:3]) == colour          # green target, red obstacle
        assert m.body_pos[g.bodyid[0]][2] == -5


# --------------------------------------------------------------------------------------------- dynamics
def peak_speed(m, q0, ctrl, seconds):
    d = mujoco.MjData(m)
    d.qpos[:] = q0
    d.ctrl[:] = ctrl
    peak = np.zeros(m.nv)
    for _ in range(int(seconds / m.opt.timestep)):
        mujoco.mj_step(m, d)
        peak = np.maximum(peak, np.abs(d.qvel))
    assert np.isfinite(d.qpos).all()
    return peak


# Worst-case full-range steps (ctrl held from rest), as found by `python assets/derive.py ROBOT`:
# all joints at once ('+' = from the lower to the upper limit, '-' the other way), and single joints
# (joint index, '+'/'-') with gravity helping, from a hand-picked pose: upper arm horizontal.
WORST = {
    "ur5e": [("+--+++", None), ("----++", None), ("-++-++", None), ("++++-+", None),
             ((1, "-"), [0, 0, 0, 0, 0, 0])],                    # lift alone, arm stretched out
    "panda": [("--+-++-", None), ("++++++-", None), ("++-+-+-", None),
              ((1, "+"), [0, 0, 0, -0.0698, 0, PI / 2, 0]),      # joint 2 alone, arm straight
              ((2, "+"), [0, PI / 2, 0, -PI / 2, 0, PI / 2, 0]),  # joint 3 alone, forearm sideways
              ((3, "-"), [0, PI / 2, 0, -PI / 2, 0, PI / 2, 0])],
}


def step_scenario(m, spec, pose):
    lo, hi = m.jnt_range.T
    if pose is None:
        up = np.array([c == "+" for c in spec])
        return np.where(up, lo, hi), np.where(up, hi, lo)
    (j, direction), q0 = spec, np.array(pose, float)
    ctrl = q0.copy()
    q0[j], ctrl[j] = (lo[j], hi[j]) if direction == "+" else (hi[j], lo[j])
    return q0, ctrl


@pytest.mark.parametrize("robot_name", ROBOTS)
def test_full_range_steps_stay_within_speed_limits(robot_name):
    m, s = load(robot_name), SPEC[robot_name]
    lo, hi = m.jnt_range.T
    vmax = np.array(s["vmax"])
    seconds = float(np.max((hi - lo) / (0.4 * vmax))) + 1.0
    worst = np.zeros(m.nv)
    for spec, pose in WORST[robot_name]:
        worst = np.maximum(worst, peak_speed(m, *step_scenario(m, spec, pose), seconds))
    assert (worst <= vmax).all(), worst / vmax
    assert (worst >= 0.85 * vmax).all(), worst / vmax          # realistic, not sluggish


@pytest.mark.parametrize("robot_name", ROBOTS)
def test_saturated_first_joint_runs_at_torque_over_damping(robot_name):
    """Joint 1 (vertical axis, no gravity) alone, full-range step: terminal speed = torque limit / damping."""
    m = load(robot_name)
    lo, hi = m.jnt_range.T
    q0 = np.clip(m.key("home").qpos, lo, hi)
    q0[0], ctrl = lo[0], q0.copy()
    ctrl[0] = hi[0]
    peak = peak_speed(m, q0, ctrl, 1.5)[0]
    expected = SPEC[robot_name]["torque"][0] / m.dof_damping[0]
    assert abs(peak - expected) < 0.02 * expected
    assert peak < SPEC[robot_name]["vmax"][0]


@pytest.mark.parametrize("pose", ["home", "zero"])
def test_holds_target_under_gravity(robot, pose):
    """At rest the servo balances gravity: kp * (ctrl - q) = gravity torque, i.e. a small sag, no drift.

    "zero" (clipped into the ranges) holds the arm stretched out: the largest gravity load, and the pose
    where an explicit (Euler) treatment of the UR5e's kv ends in a 2-step velocity limit cycle.
    """
    m = load(robot)
    d = mujoco.MjData(m)
    lo, hi = m.jnt_range.T
    q = m.key("home").qpos if pose == "home" else np.clip(np.zeros(m.nq), lo, hi)
    d.qpos[:], d.ctrl[:] = q, q
    mujoco.mj_step(m, d, 1000)                                      # 2 s
    assert np.abs(d.qvel).max() < 1e-4
    mujoco.mj_forward(m, d)
    kp = np.array(SPEC[robot]["kp"])
    # (+ the joint-limit force where "zero" was clipped onto a limit: the Panda's joint 4)
    np.testing.assert_allclose(kp * (d.ctrl - d.qpos) + d.qfrc_constraint, d.qfrc_bias, atol=0.05)
    assert np.abs(d.ctrl - d.qpos).max() < 0.04                    # <= 60 Nm / 2000, 22 Nm / 750


def test_random_ctrl_is_stable(robot):
    m = load(robot)
    d = mujoco.MjData(m)
    rng = np.random.default_rng(0)
    lo, hi = m.jnt_range.T
    for _ in range(2):
        mujoco.mj_resetData(m, d)
        d.qpos[:] = rng.uniform(lo, hi)
        for k in range(1500):                                       # 3 s, new ctrl every 40 ms
            if k % 20 == 0:
                d.ctrl[:] = rng.uniform(lo, hi)
            mujoco.mj_step(m, d)
        assert np.isfinite(d.qpos).all()
        assert np.isfinite(d.qvel).all()
        assert (d.qpos >= lo - 1e-3).all()
        assert (d.qpos <= hi + 1e-3).all()
        assert all(w.number == 0 for w in d.warning)


# --------------------------------------------------------------------------------------- collision pairs
def test_pairs_are_between_non_adjacent_bodies(robot):
    m = load(robot)
    names = pair_names(m)
    assert len(set(map(frozenset, names))) == len(names)
    for k in range(m.npair):
        b1, b2 = m.geom_bodyid[m.pair_geom1[k]], m.geom_bodyid[m.pair_geom2[k]]
        assert b1 != b2, names[k]
        assert m.body_parentid[b1] != b2, names[k]
        assert m.body_parentid[b2] != b1, names[k]
    assert all("target" not in p for p in names)


def test_obstacle_pairs_cover_every_moving_geom(robot):
    m, s = load(robot), SPEC[robot]
    paired = {a if b == "obstacle" else b for a, b in pair_names(m) if "obstacle" in (a, b)}
    assert paired == set(s["geoms"]) - s["not_near_obstacle"]


def test_every_obstacle_pair_touches(robot):
    """Obstacle centred on a capsule's centre (on its segment): signed distance = -(r + 0.1)."""
    m = with_contacts(robot)
    d = mujoco.MjData(m)
    q = m.key("home").qpos
    for a, b in pair_names(m):
        if "obstacle" not in (a, b):
            continue
        g = a if b == "obstacle" else b
        d.qpos[:] = q
        mujoco.mj_kinematics(m, d)
        d.mocap_pos[m.body_mocapid[m.body("obstacle").id]] = d.geom(g).xpos
        found = contacts(m, d, q)
        assert found[frozenset((g, "obstacle"))] == pytest.approx(-(m.geom(g).size[0] + 0.1), abs=1e-6)


# Pairs too rare for 20,000 uniform samples, with a configuration that shows the contact:
# joint 2 at its upper stop and the elbow fully folded bring the forearm down onto link1's top.
WITNESS = {
    "panda": {("link1", "link5_a"): [0.0, 1.7628, 0.0, -3.0718, 0.0, 3.7525, 0.0]},
    "ur5e": {},
}


def test_every_self_pair_is_seen_in_contact(robot):
    m = with_contacts(robot)
    d = mujoco.MjData(m)
    lo, hi = m.jnt_range.T
    self_pairs = {frozenset(p) for p in pair_names(m) if "obstacle" not in p}
    seen = set()
    for q in np.random.default_rng(0).uniform(lo, hi, size=(20_000, m.nq)):
        seen |= {k for k, dist in contacts(m, d, q).items() if dist < 0}
    for pair, q in WITNESS[robot].items():
        assert contacts(m, d, q).get(frozenset(pair), 0.0) < 0, pair
        seen.add(frozenset(pair))
    assert self_pairs <= seen, self_pairs - seen


def test_known_colliding_poses():
    # UR5e, wrist folded onto the forearm: wrist_1 = pi/2 points wrist_2's axis back along the forearm
    # (wrist_3 sits 0.100 m back from the wrist), wrist_2 = pi turns the flange towards the forearm axis.
    # The wrist_3 capsule then ends 0.127 - 0.100 = 0.027 m from forearm_b's axis:
    # distance = 0.027 - 0.038 - 0.040 = -0.051 m; wrist_2_b ends 0.127 - 0.060 away: -0.011 m.
    m = with_contacts("ur5e")
    found = contacts(m, mujoco.MjData(m), [0, -PI / 2, 0, PI / 2, PI, 0])
    assert found[frozenset(("forearm_b", "wrist_3"))] == pytest.approx(0.027 - 0.078, abs=1e-6)
    assert found[frozenset(("forearm_b", "wrist_2_b"))] == pytest.approx(0.067 - 0.078, abs=1e-6)

    # Panda, hand folded back against the forearm: joints 1-3 = 0, joint 4 = -pi/2 (forearm horizontal,
    # wrist at x = 0.0825 + 0.384, z = 0.649 + 0.0825), joint 6 = 0 (hand pointing back along -x,
    # 0.088 below the forearm axis), joint 7 = -pi/4 (finger capsule vertical).
    # link5_a spans x in [0.1565, 0.2565] at z = 0.7315, r 0.06; fingers: x = 0.4665 - 0.207 = 0.2595,
    # z in [0.5935, 0.6935], r 0.02; hand: x = 0.4665 - 0.147 = 0.3195, same z span, r 0.04.
    m = with_contacts("panda")
    found = contacts(m, mujoco.MjData(m), [0, 0, 0, -PI / 2, 0, 0, -PI / 4])
    assert found[frozenset(("link5_a", "fingers"))] == pytest.approx(np.hypot(0.003, 0.038) - 0.08, abs=1e-6)
    assert found[frozenset(("link5_a", "hand"))] == pytest.approx(np.hypot(0.063, 0.038) - 0.10, abs=1e-6)


def test_home_is_collision_free(robot):
    m = with_contacts(robot)
    d = mujoco.MjData(m)
    mujoco.mj_resetDataKeyframe(m, d, m.key("home").id)
    assert contacts(m, d, d.qpos.copy()) == {}
    for k in range(m.npair):
        if "obstacle" not in pair_names(m)[k]:
            assert mujoco.mj_geomDistance(m, d, m.pair_geom1[k], m.pair_geom2[k], 1.0, None) > 0.05
