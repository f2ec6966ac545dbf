"""tools/failure_report.py: episode outcomes read from recorded poses, with CPU MuJoCo as the reference.
"""

import datetime
import json
import os
import shlex

import mujoco
import numpy as np

import envs
from agents import evaluation, provenance
from envs import collision
from eval_runs import ROOT
from mujoco_reference import colliding_configuration, colliding_pairs, contact_model, ee_position
from tools import failure_report


def test_failure_report_names_the_colliding_pair_and_bins_the_misses(monkeypatch):
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
    a, b = np.zeros(3), np.array([1.0, 0.0, 0.0])
    centers = np.array([[0.5, 0.3, 0.0], [0.5, 0.05, 0.0], [1.5, 0.0, 0.0], [-0.3, 0.4, 0.0]])
    # beside the middle: 0.3 - 0.1; through the line: 0.05 - 0.1; past b: 0.5 - 0.1; behind a: 0.5 - 0.1
    np.testing.assert_allclose(collision.point_segment_distance(centers, a, b) - 0.1, [0.2, -0.05, 0.4, 0.4], atol=1e-6)
    np.testing.assert_allclose(collision.point_segment_distance(np.array([0.0, 0.0, 0.3]), a, a) - 0.1, 0.2, atol=1e-6)


def test_failure_report_tells_when_the_obstacle_is_in_the_way():
    """The end effector's position comes from CPU MuJoCo; the obstacle sits on the straight line to the
    target in env 1 (which misses) and beside it in env 0 (which reaches)."""
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
    """--json holds the command, code, device and date (agents/provenance.py); the rollout and its reading are
    stubbed: only the shipped policy's export is loaded."""
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
    monkeypatch.setattr(evaluation, "rollout", lambda *a, **k: None)
    monkeypatch.setattr(failure_report, "classify", lambda *a, **k: [])
    monkeypatch.setattr(failure_report, "summarize", lambda rows, near_limit=None: {"episodes": 0})
    monkeypatch.setattr(failure_report, "markdown", lambda summary, title: "")
    out, checkpoint = tmp_path / "report.json", os.path.join(ROOT, "results", "checkpoints", "ur5e-reach-ppo")
    out.write_text("the report of an earlier run")
    monkeypatch.setattr(provenance, "code_version", lambda: out.read_text())
    failure_report.main(["--checkpoint", checkpoint, "--num-envs", "1", "--json", str(out)])
    assert json.loads(out.read_text())["code"] == "the report of an earlier run"
