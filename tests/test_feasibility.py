"""tools/feasibility.py: the inverse-kinematics search against targets whose answer is known, and its refusals."""

import json

import jax
import jax.numpy as jnp
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
    found = fz.search_episode(ur5e, free, jax.random.PRNGKey(0), fz.SearchConfig(restarts=8))
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
    found = fz.search_episode(ur5e, swallowed, jax.random.PRNGKey(0), fz.SearchConfig(restarts=8))
    assert not bool(found)


def test_the_target_configuration_collides_in_a_swallowing_obstacle(ur5e, info):
    swallowed = _with(info, obstacle_pos=info["target_pos"])
    assert float(fz.pose_check(ur5e, swallowed, info["target_qpos"])[1]) < 0.0


def test_the_target_configuration_reaches_its_target(ur5e, info):
    """The pose that defined the target puts the end effector on it (what `feasibility` tries first)."""
    assert float(fz.pose_check(ur5e, info, info["target_qpos"])[0]) < 1e-5


def test_the_report_names_its_command(tmp_path):
    path = tmp_path / "feasibility.json"
    fz.main(["ur5e-reach-avoid", "--episodes", "4", "--restarts", "2", "--iterations", "10", "--json", str(path)])
    assert "tools.feasibility" in json.loads(path.read_text())["command"]


@pytest.fixture(scope="module")
def four(ur5e):
    """The report on four episodes among 0.3 m obstacles: all far away but in the third, which swallows the target;
    in the fourth the target is moved out of reach."""
    infos = fz.reset_infos(ur5e, 4, seed=0)
    far_obstacles = infos["obstacle_pos"].at[:].set(_FAR)
    infos = {**infos, "obstacle_pos": far_obstacles.at[2].set(infos["target_pos"][2])}
    infos = {**infos, "target_pos": infos["target_pos"].at[3].set(_FAR / 2)}
    return fz.feasibility(ur5e, infos, seed=0, search=fz.SearchConfig(restarts=4, iterations=50))


def test_the_report_names_the_infeasible_episodes(four):
    assert four["infeasible_episodes"] == [2, 3]


def test_the_target_configuration_is_clear_in_half_of_them(four):
    """Episodes 0 and 1 (obstacles far away, targets set by their own poses); not 2 (swallowed) nor 3 (moved)."""
    assert four["target_pose_clear"] == 0.5


def _found(env, clearance_step):
    search = fz.SearchConfig(restarts=2, iterations=100, clearance_step=clearance_step)
    return fz.feasibility(env, fz.reset_infos(env, 64, seed=0), seed=1, search=search)["found_by_search"]


def test_the_null_space_step_finds_poses_that_plain_least_squares_misses(ur5e):
    """64 episodes among 0.3 m obstacles, two starts each: pushing away from the nearest collision finds a clear
    pose in more of the blocked episodes (4 against 2 when measured)."""
    assert _found(ur5e, 0.5) > _found(ur5e, 1e-9)


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
