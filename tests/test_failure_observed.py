"""tools/failure_report.py's readings on the step an obstacle collision's last action was chosen from:
`origin_distance_before` (the paper's link distance from each link frame's origin, as observed) against CPU MuJoCo's
link origins, and `surface_distance_before` (the robot's true clearance) against CPU MuJoCo's `mj_geomDistance`."""

import mujoco
import numpy as np
import pytest

import envs
from mujoco_reference import contact_model
from tools import failure_report

FAR = np.array([1.0, 1.0, 1.0])
"""Where the second obstacle (radius 0.12 m) stays: far from the arm, so the first one is the nearest."""


def _forearm_contact(before: float, turn: float = 0.0, steps: int = 3):
    """The UR5e with its elbow bent; obstacle 1 (radius 0.05 m) `before` m off the middle of the forearm (between the
    forearm's and wrist 1's frame origins, CPU MuJoCo) on the steps before `steps` and 0.05 m off it at `steps`, an
    obstacle collision; obstacle 2 (radius 0.12 m) at `FAR`. At `steps` the base joint has turned by `turn` rad, so
    only the step before gives the pose the readings expect. Returns the robot, the records and the pose before."""
    robot = envs.make("ur5e-reach-avoid").robot
    qpos = np.zeros(robot.nq)
    qpos[1], qpos[2] = -1.2, 1.0
    data = mujoco.MjData(robot.mj_model)
    data.qpos[:] = qpos
    mujoco.mj_kinematics(robot.mj_model, data)
    forearm, wrist = data.body("forearm_link").xpos, data.body("wrist_1_link").xpos
    middle = (forearm + wrist) / 2
    side = np.cross(wrist - forearm, [0.0, 0.0, 1.0])
    side = side / np.linalg.norm(side)
    near = np.tile(middle + before * side, (steps + 1, 1, 1))
    near[steps] = middle + 0.05 * side
    poses = np.tile(qpos, (steps + 1, 1, 1))
    poses[steps, 0, 0] += turn
    metrics = {"episode/self_collision": np.zeros(1), "episode/obstacle_collision": np.ones(1),
               "episode/target_reached": np.zeros(1), "episode/distance": np.array([0.4])}
    records = {"qpos": poses, "obstacle_pos": np.concatenate([near, np.tile(FAR, (steps + 1, 1, 1))], axis=-1),
               "obstacle_radius": np.tile([0.05, 0.12], (steps + 1, 1, 1)), "length": np.array([steps]),
               "metrics": metrics, "target_pos": np.tile(wrist + [0.4, 0.0, 0.0], (steps + 1, 1, 1))}
    return robot, records, qpos


def _link_origins(robot, qpos):
    data = mujoco.MjData(robot.mj_model)
    data.qpos[:] = qpos
    mujoco.mj_kinematics(robot.mj_model, data)
    return data.xpos[robot.link_bodies]


def test_the_reading_is_the_nearest_link_origins_distance_to_the_nearest_surface_on_the_step_before():
    robot, records, pose = _forearm_contact(before=0.15, turn=0.3)
    origins = _link_origins(robot, pose)
    expected = min(np.min(np.linalg.norm(origins - centre, axis=-1)) - radius
                   for centre, radius in ((records["obstacle_pos"][2, 0, :3], 0.05), (FAR, 0.12)))
    row = failure_report.classify(robot, records)[0]
    assert row["origin_distance_before"] == pytest.approx(expected, abs=1e-5)


def test_a_contact_mid_forearm_reads_over_10_cm_from_every_link_origin():
    robot, records, _ = _forearm_contact(before=0.05)  # touching on the step before too
    row = failure_report.classify(robot, records)[0]
    assert row["what"].startswith("forearm")
    assert row["origin_distance_before"] > 0.1


def test_the_true_clearance_is_the_robots_capsules_distance_to_the_nearest_sphere_on_the_step_before():
    robot, records, pose = _forearm_contact(before=0.15, turn=0.3)
    row = failure_report.classify(robot, records)[0]
    expected = []
    for centre, radius in ((records["obstacle_pos"][2, 0, :3], 0.05), (FAR, 0.12)):
        model = contact_model(robot, obstacle_radius=radius)
        data = mujoco.MjData(model)
        data.qpos[:] = pose
        data.mocap_pos[robot.obstacle_mocap] = centre
        mujoco.mj_kinematics(model, data)
        expected += [mujoco.mj_geomDistance(model, data, model.geom("obstacle").id, int(g), 1.0, None)
                     for g in robot.obstacle_geoms]
    assert row["surface_distance_before"] == pytest.approx(min(expected), abs=1e-4)


def _rows():
    return [{"outcome": "obstacle collision", "what": "g", "step": 9, "start_clearance": 0.1,
             "origin_distance_before": d, "surface_distance_before": d / 10, "at_limit": [], "end_motion": 0.0,
             "joint_margin": 1.0} for d in (0.05, 0.2, 0.3)]


def test_the_summary_gives_the_median_reading_and_the_share_over_10_cm():
    collisions = failure_report.summarize(_rows())["collisions"]
    assert collisions["origin_distance_before"] == pytest.approx({"median": 0.2, "share_over_10cm": 2 / 3})
    assert collisions["surface_distance_before"] == pytest.approx({"median": 0.02, "share_over_10cm": 0.0})


def test_the_report_prints_both_readings():
    text = failure_report.markdown(failure_report.summarize(_rows()), "t")
    assert '(the paper\'s d_i, observed with link_distance="origin"): median 20.0 cm, over 10 cm in 66.7 %' in text
    assert ('true clearance from the obstacles on the step before (observed with link_distance="surface"): '
            "median 2.0 cm, over 10 cm in 0.0 %") in text
