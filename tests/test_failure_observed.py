"""tools/failure_report.py's `origin_distance_before`: what the paper's link distance (from each link frame's
origin) read on the step an obstacle collision's last action was chosen from, against CPU MuJoCo's link origins."""

import mujoco
import numpy as np
import pytest

import envs
from mujoco_reference import contact_model
from tools import failure_report


def _forearm_contact(before: float, steps: int = 3):
    """The UR5e with its elbow bent and one obstacle of radius 0.05 m centred 0.05 m off the middle of the forearm
    (between the forearm's and wrist 1's frame origins, CPU MuJoCo) at `steps`, an obstacle collision, and `before` m
    off it on the steps before; and the reading expected on the step before."""
    robot = envs.make("ur5e-reach-avoid").robot
    qpos = np.zeros(robot.nq)
    qpos[1], qpos[2] = -1.2, 1.0
    data = mujoco.MjData(robot.mj_model)
    data.qpos[:] = qpos
    mujoco.mj_kinematics(robot.mj_model, data)
    origins = data.xpos[robot.link_bodies]  # the links' frame origins, in link_bodies order
    forearm, wrist = data.body("forearm_link").xpos, data.body("wrist_1_link").xpos
    middle = (forearm + wrist) / 2
    side = np.cross(wrist - forearm, [0.0, 0.0, 1.0])
    side = side / np.linalg.norm(side)
    path = np.tile(middle + before * side, (steps + 1, 1, 1))
    path[steps] = middle + 0.05 * side
    metrics = {"episode/self_collision": np.zeros(1), "episode/obstacle_collision": np.ones(1),
               "episode/target_reached": np.zeros(1), "episode/distance": np.array([0.4])}
    records = {"qpos": np.tile(qpos, (steps + 1, 1, 1)), "obstacle_pos": path,
               "obstacle_radius": np.full((steps + 1, 1, 1), 0.05), "length": np.array([steps]), "metrics": metrics,
               "target_pos": np.tile(wrist + [0.4, 0.0, 0.0], (steps + 1, 1, 1))}
    return robot, records, np.min(np.linalg.norm(origins - path[steps - 1, 0], axis=-1)) - 0.05


def test_the_reading_is_the_nearest_link_origins_distance_to_the_obstacle_surface_on_the_step_before():
    robot, records, expected = _forearm_contact(before=0.15)
    row = failure_report.classify(robot, records)[0]
    assert row["origin_distance_before"] == pytest.approx(expected, abs=1e-5)


def test_a_contact_mid_forearm_reads_over_10_cm_from_every_link_origin():
    robot, records, _ = _forearm_contact(before=0.05)  # touching on the step before too
    row = failure_report.classify(robot, records)[0]
    assert row["what"].startswith("forearm")
    assert row["origin_distance_before"] > 0.1


def test_the_true_clearance_on_the_step_before_is_the_forearm_capsules_distance_to_the_sphere():
    """Touching on the step before too: the robot's smallest capsule-to-sphere distance then, from CPU MuJoCo's
    `mj_geomDistance` (the same obstacle and pose as at the collision, so the same clearance)."""
    robot, records, _ = _forearm_contact(before=0.05)
    row = failure_report.classify(robot, records)[0]
    model = contact_model(robot, obstacle_radius=0.05)
    data = mujoco.MjData(model)
    data.qpos[:] = records["qpos"][2, 0]
    data.mocap_pos[robot.obstacle_mocap] = records["obstacle_pos"][2, 0]
    mujoco.mj_kinematics(model, data)
    expected = min(mujoco.mj_geomDistance(model, data, model.geom("obstacle").id, int(g), 1.0, None)
                   for g in robot.obstacle_geoms)
    assert row["surface_distance_before"] == pytest.approx(expected, abs=1e-4)


def test_the_summary_gives_the_median_reading_and_the_share_over_10_cm():
    rows = [{"outcome": "obstacle collision", "what": "g", "step": 9, "start_clearance": 0.1,
             "origin_distance_before": d, "surface_distance_before": d / 10, "at_limit": [], "end_motion": 0.0,
             "joint_margin": 1.0} for d in (0.05, 0.2, 0.3)]
    collisions = failure_report.summarize(rows)["collisions"]
    assert collisions["origin_distance_before"] == pytest.approx({"median": 0.2, "share_over_10cm": 2 / 3})
    assert collisions["surface_distance_before"] == pytest.approx({"median": 0.02, "share_over_10cm": 0.0})
