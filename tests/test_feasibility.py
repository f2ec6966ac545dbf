"""tools/feasibility.py: the inverse-kinematics search against targets whose answer is known, and its refusals."""

import json

import jax
import jax.numpy as jnp
import numpy as np
import pytest

from tools import feasibility as fz

_FAR = jnp.array([10.0, 10.0, 10.0])


@pytest.fixture(scope="module")
def ur5e():
    return fz.arm_env("ur5e-reach-avoid", {"obstacle_radius": 0.3})


@pytest.fixture(scope="module")
def info(ur5e):
    return ur5e.reset(jax.random.PRNGKey(3)).info


def _with(info, **fields):
    return {**info, **fields}


def test_the_search_reaches_a_target_set_by_a_known_pose(ur5e, info):
    """A target placed where a collision-free pose puts the end effector (the obstacle moved far away) is found
    from random starts, not from that pose."""
    pose = jnp.array([0.3, -1.2, 1.0, -1.3, -1.5, 0.4])
    target = ur5e.robot.kinematics(pose).ee_pos
    free = _with(info, target_pos=target, obstacle_pos=_FAR)
    assert float(fz.pose_check(ur5e, free, pose)[1]) > 0.0  # the pose itself is collision-free
    found, _ = fz.search_episode(ur5e, free, jax.random.PRNGKey(0), fz.SearchConfig(restarts=8))
    assert bool(found)


def test_a_solved_pose_ends_within_a_millimetre_of_the_target(ur5e, info):
    pose = jnp.array([0.3, -1.2, 1.0, -1.3, -1.5, 0.4])
    target = ur5e.robot.kinematics(pose).ee_pos
    free = _with(info, target_pos=target, obstacle_pos=_FAR)
    starts = jax.random.uniform(jax.random.PRNGKey(1), (8, 6), minval=ur5e.robot.joint_low,
                                maxval=ur5e.robot.joint_high)
    ends = jax.vmap(lambda q: fz.solve(ur5e, free, q, fz.SearchConfig()))(starts)
    distances = jax.vmap(lambda q: fz.pose_check(ur5e, free, q)[0])(ends)
    assert float(jnp.min(distances)) < 1e-3


def test_no_pose_is_clear_inside_an_obstacle_that_swallows_the_target(ur5e, info):
    """A sphere of radius 0.3 m centred on the target: an end effector within 2 cm of its centre has its last
    link inside it, so no configuration counts."""
    swallowed = _with(info, obstacle_pos=info["target_pos"])
    found, _ = fz.search_episode(ur5e, swallowed, jax.random.PRNGKey(0), fz.SearchConfig(restarts=8))
    assert not bool(found)


def test_the_target_configuration_collides_in_a_swallowing_obstacle(ur5e, info):
    swallowed = _with(info, obstacle_pos=info["target_pos"])
    assert float(fz.pose_check(ur5e, swallowed, info["target_qpos"])[1]) < 0.0


def test_the_target_configuration_reaches_its_target(ur5e, info):
    """The pose that defined the target puts the end effector on it (what `feasibility` tries first)."""
    assert float(fz.pose_check(ur5e, info, info["target_qpos"])[0]) < 1e-5


def test_the_report_counts_the_infeasible_episodes(tmp_path):
    path = tmp_path / "feasibility.json"
    fz.main(["ur5e-reach-avoid", "--episodes", "16", "--restarts", "4", "--iterations", "50",
             "--json", str(path)])
    report = json.loads(path.read_text())
    assert report["feasible"] == pytest.approx(1 - len(report["infeasible_episodes"]) / 16)


def test_the_report_names_its_command(tmp_path):
    path = tmp_path / "feasibility.json"
    fz.main(["ur5e-reach-avoid", "--episodes", "4", "--restarts", "2", "--iterations", "10", "--json", str(path)])
    assert "tools.feasibility" in json.loads(path.read_text())["command"]


def test_searched_episodes_are_those_whose_target_configuration_collides(ur5e):
    """With a 0.3 m obstacle many target configurations collide; the search adds no more episodes than those."""
    result = fz.feasibility(ur5e, 32, seed=0, search=fz.SearchConfig(restarts=2, iterations=10))
    blocked = int(round((1 - result["target_pose_clear"]) * 32))
    assert result["found_by_search"] <= blocked


def _found(env, clearance_step):
    search = fz.SearchConfig(restarts=2, iterations=100, clearance_step=clearance_step)
    return fz.feasibility(env, 64, seed=0, search=search)["found_by_search"]


def test_the_null_space_step_finds_poses_that_plain_least_squares_misses(ur5e):
    """64 episodes among 0.3 m obstacles, two starts each: pushing away from the nearest collision finds a clear
    pose in more of the blocked episodes (5 against 3 when measured)."""
    assert _found(ur5e, 0.5) > _found(ur5e, 1e-9)


def test_the_clearances_are_the_target_configurations(ur5e):
    result = fz.feasibility(ur5e, 4, seed=0, search=fz.SearchConfig(restarts=2, iterations=10))
    infos = jax.vmap(lambda k: ur5e.reset(k).info)(jax.random.split(jax.random.PRNGKey(0), 4))
    expected = [float(fz.pose_check(ur5e, jax.tree.map(lambda x: x[i], infos), infos["target_qpos"][i])[1])
                for i in range(4)]
    assert np.allclose(result["target_pose_clearance"], expected, atol=1e-6)


@pytest.mark.parametrize("field, value", [("restarts", 0), ("iterations", 1.5), ("damping", 0.0),
                                          ("margin", -0.1), ("clearance_step", True)])
def test_impossible_search_settings_are_refused_naming_the_field(field, value):
    with pytest.raises(ValueError, match=f"{field}="):
        fz.SearchConfig(**{field: value})


def test_moving_obstacles_are_refused():
    with pytest.raises(ValueError, match="obstacle_motion='linear' is invalid"):
        fz.arm_env("ur5e-reach-avoid", {"obstacle_motion": "linear"})


def test_an_env_without_an_arm_is_refused():
    with pytest.raises(ValueError, match="env='point-mass' is invalid"):
        fz.arm_env("point-mass")


def test_an_option_without_a_value_is_refused():
    with pytest.raises(ValueError, match="--option 'obstacle_radius' is invalid"):
        fz.main(["ur5e-reach-avoid", "--option", "obstacle_radius"])
