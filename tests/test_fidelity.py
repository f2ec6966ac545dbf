"""tools.fidelity, the learner-free UR5e measurements, against hand-computed numbers and a plain MuJoCo loop.

The tool's numbers go into results/fidelity beside the paper's baseline table, so each piece is checked on
inputs whose answer is known without the tool:
- `episode_summary` on hand-made records of four episodes (reached at 0.01 / 0.02 m, a collision, steps after
  `done`, end distances, end poses) with the real UR5e's joint limits; `rate`'s binomial standard error;
  `limit_margins` on hand-picked poses; `pseudo_ik_targets` on hand-picked angles.
- `rollout`, the pseudo-IK agent under absolute control on the native backend, against `mj_step` called by a
  plain Python loop on the env's MuJoCo model with the servo targets that agent commands.
- the command line: its validation names the offending value, and a tiny run writes the provenance and one
  baselines row per (action, agent).

MuJoCo and JAX are kept cheap on a CPU: one UR5e env of 30-step episodes, two episodes per rollout, one tiny
command-line run (each rollout costs a 10-15 s compile; the file takes about 40 s on a 2-core CPU without
the persistent compilation cache).
"""

import json
import re
from types import SimpleNamespace

import jax
import mujoco
import numpy as np
import pytest

from mujoco_reference import colliding_configuration, colliding_pairs, contact_model
import envs
from tools import fidelity, fidelity_train

STEPS = 30
"""Episode length of the test env (the pseudo-IK episode below reaches 0.02 m at its 27th step)."""


@pytest.fixture(scope="module")
def env():
    """The UR5e reach env as the tool builds it: absolute control, short episodes, no variant."""
    return fidelity.build({"action": "absolute", "episode_length": STEPS}, [])


# ------------------------------------------------------------------------------------------------
# episode_summary on hand-made records

RECORD_STEPS = 12
# Four episodes, 12 steps each. A: reaches 0.01 m, runs to the end. B: gets to 0.015 m, drifts away, ends with
# joint 0 pinned 0.03 rad from its limit and 0.5 rad from the goal. C: within 0.005 m at step 3, collides at
# step 4 (a collided episode never counts as reached, pinned or far). D: done at step 5 without a collision
# (at 0.015 m), then 0.005 m and a pinned, far pose that must not count.
DISTANCES = np.array([
    [0.5, 0.4, 0.3, 0.2, 0.1, 0.05, 0.02, 0.008, 0.005, 0.006, 0.007, 0.009],  # A
    [0.6, 0.5, 0.3, 0.1, 0.015, 0.05, 0.1, 0.2, 0.3, 0.3, 0.3, 0.3],  # B
    [0.4, 0.2, 0.05, 0.005, 0.3, 0.001, 0.001, 0.001, 0.001, 0.001, 0.001, 0.001],  # C
    [0.3, 0.2, 0.1, 0.05, 0.03, 0.015, 0.005, 0.005, 0.005, 0.005, 0.005, 0.005],  # D
]).T  # [steps, episodes], as `rollout` records them


@pytest.fixture(scope="module")
def hand_made(env):
    """(records, goal, collided end pose) of the four episodes above."""
    robot = env.robot
    low, high = robot.joint_low.astype(np.float64), robot.joint_high.astype(np.float64)
    coll = np.zeros((RECORD_STEPS, 4))
    coll[4, 2] = 1.0  # C collides at step 4
    done = np.zeros((RECORD_STEPS, 4))
    done[-1] = 1.0  # every episode is truncated at the last step
    done[4, 2] = done[5, 3] = 1.0  # C ends at its collision, D at step 5

    a_end = np.zeros(6)
    a_end[4] = high[4] - 0.06  # 0.06 rad from the limit: not pinned
    b_end = np.zeros(6)
    b_end[0] = high[0] - 0.03  # pinned
    c_end = colliding_configuration(robot, seed=3).astype(np.float64)
    c_end[0] = high[0] - 0.01  # pinned too (the base joint turns the whole arm: still colliding)
    d_end = np.full(6, 0.2)
    d_late = d_end.copy()
    d_late[2] = low[2] + 0.01  # pinned and 0.2 + pi rad from the goal, but after `done`

    qpos = np.zeros((RECORD_STEPS, 4, 6))
    qpos[:, 0], qpos[:, 1], qpos[:, 2] = a_end, b_end, c_end
    qpos[:6, 3], qpos[6:, 3] = d_end, d_late
    goal = np.stack([a_end - np.array([0, 0, 0, 0.09, 0, 0]),  # 0.09 rad off: not far
                     b_end - np.array([0.5, 0, 0, 0, 0, 0]),  # far
                     c_end + 0.5,  # far, but collided
                     d_end])
    return (DISTANCES, coll, done, qpos.astype(np.float32)), goal, c_end


@pytest.fixture(scope="module")
def summary(env, hand_made):
    records, goal, _ = hand_made
    return fidelity.episode_summary(env, records, goal)


def test_summary_reached_at_one_centimetre_excludes_collided_and_after_done(summary):
    assert summary["reached_0.01"]["rate"] == pytest.approx(1 / 4)  # A (not C: collided; not D: after done)


def test_summary_reached_at_two_centimetres(summary):
    assert summary["reached_0.02"]["rate"] == pytest.approx(3 / 4)  # A, B, D before its done; not C


def test_summary_self_collision_rate_and_step(summary):
    assert summary["self_collision"]["rate"] == pytest.approx(1 / 4)
    assert summary["collision_step_mean"] == pytest.approx(5.0)  # C's collision on its 5th step


def test_summary_collision_pair_is_one_mujoco_finds(env, summary, hand_made):
    """The pair `collision_pairs` names for C's end pose is one CPU MuJoCo's collision detection finds."""
    robot, c_end = env.robot, hand_made[2]
    found = colliding_pairs(contact_model(robot), c_end)
    names = {" - ".join(robot.mj_model.geom(g).name for g in pair) for pair in found}
    names |= {" - ".join(robot.mj_model.geom(g).name for g in pair[::-1]) for pair in found}
    assert list(summary["collision_pairs"].values()) == [1.0]
    assert next(iter(summary["collision_pairs"])) in names


def test_summary_distance_at_the_end(summary):
    # A's last step, B's last step, C's collision step, D's done step
    assert summary["distance"]["mean"] == pytest.approx(np.mean([0.009, 0.3, 0.3, 0.015]))


def test_summary_last_ten_steps_with_collided_as_zero(summary):
    # A: steps 2-11, B: steps 2-11, C: 0 (collided), D: steps 0-5 (fewer than 10 before done)
    last10 = [0.705 / 10, 1.965 / 10, 0.0, 0.695 / 6]
    assert summary["distance_last10_collided0"]["mean"] == pytest.approx(np.mean(last10))


def test_summary_pinned_at_end(summary):
    assert summary["pinned_at_end"]["rate"] == pytest.approx(1 / 4)  # B (A 0.06 rad off; C collided; D late)


def test_summary_far_from_goal_at_end(summary):
    assert summary["far_from_goal_at_end"]["rate"] == pytest.approx(1 / 4)  # B (A 0.09 rad; C collided; D late)


def test_rate_binomial_standard_error():
    r = fidelity.rate([1, 0, 0, 0])
    assert r["rate"] == 0.25
    assert r["se"] == pytest.approx(np.sqrt(0.25 * 0.75 / 4))


def test_rate_of_a_certain_outcome_has_no_error():
    assert fidelity.rate([1, 1, 1]) == {"rate": 1.0, "se": 0.0}


# ------------------------------------------------------------------------------------------------
# limit_margins and pseudo_ik_targets on hand-picked poses

def test_limit_margins_shares(env):
    """Start poses: joint 3 at its upper limit, joint 1 0.3 rad above its lower limit, the middle. Targets:
    the elbow (+-pi) 0.05 rad from its limit, then twice the middle."""
    low, high = env.robot.joint_low, env.robot.joint_high
    start_q = np.zeros((3, 6), np.float32)
    start_q[0, 3] = high[3]
    start_q[1, 1] = low[1] + np.float32(0.3)
    target_q = np.zeros((3, 6), np.float32)
    target_q[0, 2] = high[2] - np.float32(0.05)
    start = SimpleNamespace(pipeline_state=SimpleNamespace(qpos=start_q), info={"target_qpos": target_q})
    m = fidelity.limit_margins(env, start)
    assert m["start"]["0.1"]["any_joint"] == pytest.approx(1 / 3)
    assert m["start"]["0.1"]["per_joint"] == pytest.approx([0, 0, 0, 1 / 3, 0, 0])
    assert m["start"]["0.5"]["any_joint"] == pytest.approx(2 / 3)
    assert m["start"]["0.5"]["per_joint"] == pytest.approx([0, 1 / 3, 0, 1 / 3, 0, 0])
    assert m["target"]["0.1"]["per_joint"] == pytest.approx([0, 0, 1 / 3, 0, 0, 0])


def test_pseudo_ik_nearest_picks_the_closest_equivalent_angle_in_range(env):
    """Joint ranges: +-2 pi, the elbow (joint 2) +-pi. Row 0, per joint: target + 2 pi, target - 2 pi, target
    (target + 2 pi = 3.28 would be nearer but leaves the elbow's range), target, target (target + 2 pi = 6.38
    would be nearer but leaves the range), target - 2 pi. Row 1 starts at its target: the target itself."""
    two_pi = 2 * np.pi
    start = np.array([[5.0, -5.0, 3.0, 0.5, 6.0, -3.5], [1.0, 2.0, -1.0, 0.3, -0.2, 4.0]], np.float32)
    target = np.array([[-1.0, 1.0, -3.0, 1.0, 0.1, 3.0], [1.0, 2.0, -1.0, 0.3, -0.2, 4.0]], np.float32)
    expected = np.array([[-1.0 + two_pi, 1.0 - two_pi, -3.0, 1.0, 0.1, 3.0 - two_pi], target[1]])
    got = np.asarray(fidelity.pseudo_ik_targets(env, start, target, "nearest"))
    np.testing.assert_allclose(got, expected, atol=1e-5)


def test_pseudo_ik_sampled_commands_the_target_itself(env):
    start, target = np.full((1, 6), 5.0, np.float32), np.full((1, 6), -1.0, np.float32)
    np.testing.assert_array_equal(fidelity.pseudo_ik_targets(env, start, target, "sampled"), target)


# ------------------------------------------------------------------------------------------------
# rollout against a plain MuJoCo loop

def _nearest_angles(q0, target, low, high):
    """Per joint, the one of target, target -+ 2 pi inside [low, high] closest to q0 (a plain loop)."""
    out = []
    for j in range(len(q0)):
        options = [target[j] + k * 2 * np.pi for k in (0, -1, 1) if low[j] <= target[j] + k * 2 * np.pi <= high[j]]
        out.append(min(options, key=lambda a: abs(a - q0[j])))
    return np.array(out)


def _plain_mujoco_episode(model, q0, ctrl, target, steps, substeps):
    """(qpos, end-effector distance to `target`) after each env step: `substeps` mj_step calls holding `ctrl`."""
    data, ee = mujoco.MjData(model), model.site("ee").id
    data.qpos[:], data.ctrl[:] = q0, ctrl
    qpos, dist = [], []
    for _ in range(steps):
        mujoco.mj_step(model, data, nstep=substeps)
        mujoco.mj_kinematics(model, data)  # mj_step leaves the poses of its last substep's start
        qpos.append(data.qpos.copy())
        dist.append(np.linalg.norm(data.site_xpos[ee] - target))
    return np.array(qpos), np.array(dist)


def _ee_position(model, qpos):
    data = mujoco.MjData(model)
    data.qpos[:] = qpos
    mujoco.mj_kinematics(model, data)
    return data.site_xpos[model.site("ee").id].copy()


@pytest.fixture(scope="module")
def pseudo_ik_episodes(env):
    """The tool's pseudo-IK rollout ("nearest" angles, absolute control) of seed 4's two episodes, beside the
    same episodes from a plain MuJoCo loop in float64: goal, target, (qpos, distance) per episode. "nearest"
    because its shorter joint paths reach 0.02 m within 30 steps (episode 1 at its 27th step, index 26;
    episode 0 stays over 0.2 m away)."""
    start, goal, (dist, coll, done, qpos) = fidelity.rollout(env, "pseudo_ik", jax.random.PRNGKey(4), 2, "nearest")
    model, robot = env.robot.mj_model, env.robot
    low, high = robot.joint_low.astype(np.float64), robot.joint_high.astype(np.float64)
    reference = []
    for i in range(2):
        q0 = np.asarray(start.pipeline_state.qpos[i], np.float64)
        target_q = np.asarray(start.info["target_qpos"][i], np.float64)
        servo = _nearest_angles(q0, target_q, low, high)  # absolute actions map onto the range: the servo target
        target = _ee_position(model, target_q)
        reference.append((servo, target, *_plain_mujoco_episode(model, q0, servo, target, STEPS,
                                                                env.config.substeps)))
    return start, goal, (dist, qpos), reference


def test_rollout_goal_is_the_nearest_equivalent_pose(pseudo_ik_episodes):
    _, goal, _, reference = pseudo_ik_episodes
    np.testing.assert_allclose(goal, np.stack([r[0] for r in reference]), atol=1e-5)


def test_rollout_target_is_mujocos_end_effector_of_the_target_pose(pseudo_ik_episodes):
    start, _, _, reference = pseudo_ik_episodes
    np.testing.assert_allclose(start.info["target_pos"], np.stack([r[1] for r in reference]), atol=1e-5)


def test_rollout_joint_positions_match_a_plain_mujoco_loop(pseudo_ik_episodes):
    """Tolerance 1e-5 rad: the native backend rounds the state to float32 between env steps and the servo
    target to float32 through the action mapping (measured here: 7e-7 rad over 30 steps;
    tests/test_native_backend.py finds 125-step UR5e episodes within 1e-5 rad of a float64 loop)."""
    _, _, (dist, qpos), reference = pseudo_ik_episodes
    for i, (_, _, ref_q, _) in enumerate(reference):
        np.testing.assert_allclose(qpos[:, i], ref_q, atol=1e-5, err_msg=f"episode {i}")
    assert np.abs(qpos[-1] - qpos[0]).max() > 0.5  # the arms moved a long way


def test_rollout_distances_and_first_reach_match_a_plain_mujoco_loop(pseudo_ik_episodes):
    """Distances agree to 1e-5 m (1e-5 rad at joints within 1 m of the end effector; measured: 3e-7 m); the
    first step within 0.02 m is the same (the crossing episode is 1.8 mm either side of 0.02 m at steps 25 and
    26, far beyond the tolerance)."""
    _, _, (dist, qpos), reference = pseudo_ik_episodes
    first = lambda d: int(np.argmax(d < 0.02)) if (d < 0.02).any() else None
    for i, (_, _, _, ref_d) in enumerate(reference):
        np.testing.assert_allclose(dist[:, i], ref_d, atol=1e-5, err_msg=f"episode {i}")
    assert [first(dist[:, i]) for i in range(2)] == [first(r[3]) for r in reference]
    assert [first(r[3]) for r in reference] == [None, 26]  # one episode reaches: the comparison means something


# ------------------------------------------------------------------------------------------------
# the command line

ARGS = ["--episodes", "2", "--agents", "standstill", "--actions", "absolute", "--no-speed"]


@pytest.mark.parametrize("extra, named", [
    (["--variant", "bogus"], "'bogus'"),
    (["--variant", "damping=1,2"], "'damping=1,2'"),  # 2 factors for 6 joints
    (["--env-option", "bogus=1"], "'bogus'"),
    (["--env-option", "episode_length=ten"], "episode_length='ten'"),  # not JSON: text, which no int field takes
    (["--env-option", "episode_length"], "'episode_length'"),  # no FIELD=VALUE
    (["--env-option", "action=relative"], "action='relative'"),  # --actions sets the action mode
])
def test_invalid_option_is_named(tmp_path, extra, named):
    out = tmp_path / "x.json"
    with pytest.raises(ValueError, match=re.escape(named)):
        fidelity.main(ARGS + extra + ["--out", str(out)])
    assert not out.exists()


def test_command_line_writes_provenance_and_one_row_per_configuration(tmp_path):
    out = tmp_path / "x.json"
    fidelity.main(["--episodes", "4", "--agents", "standstill", "--actions", "absolute", "--no-speed",
                   "--env-option", f"episode_length={STEPS}", "--out", str(out)])
    result = json.loads(out.read_text())
    assert {"command", "code", "device", "date"} <= set(result)
    assert [(r["action"], r["agent"]) for r in result["baselines"]] == [("absolute", "standstill")]
    row = result["baselines"][0]
    assert row["self_collision"]["rate"] == 0.0  # holding a collision-free start pose
    rates = [v["rate"] for v in row.values() if isinstance(v, dict) and "rate" in v]
    assert len(rates) == 5
    assert all(0 <= p <= 1 for p in rates)
    assert result["env_options"] == {"episode_length": STEPS}


def test_wrist_3_variant_resizes_the_capsule_of_that_env_only():
    built = envs.make("ur5e-reach")
    g = built.robot.mj_model.geom("wrist_3").id
    fidelity.apply_variants(built, ["wrist_3=0,0.03"])
    assert built.robot.geom_half[g] == 0.0
    assert built.robot.geom_radius[g] == np.float32(0.03)
    assert envs.make("ur5e-reach").robot.geom_half[g] == np.float32(0.02)  # a new env has the model's size


def test_damping_variant_scales_the_damping_the_gpu_model_steps_with():
    built = envs.make("ur5e-reach")
    before = np.array(built.robot.mj_model.dof_damping)
    fidelity.apply_variants(built, ["damping=0.5"])
    np.testing.assert_allclose(np.asarray(built.robot.mjx_model.dof_damping), 0.5 * before, rtol=1e-6)


def test_elbow_2pi_variant_widens_the_range_the_gpu_model_clamps_to():
    built = fidelity.apply_variants(envs.make("ur5e-reach"), ["elbow_2pi"])
    np.testing.assert_allclose(np.asarray(built.robot.mjx_model.jnt_range[2]), [-2 * np.pi, 2 * np.pi], rtol=1e-6)


def test_position_servos_variant_sets_the_older_gains_on_both_models():
    built = fidelity.apply_variants(envs.make("ur5e-reach"), ["position_servos"])
    mjx_model = built.robot.mjx_model
    np.testing.assert_allclose(np.asarray(mjx_model.dof_damping), [200, 200, 200, 15, 15, 15])
    np.testing.assert_allclose(np.asarray(mjx_model.actuator_gainprm[:, 0]), [3500] * 3 + [3000] * 3)
    np.testing.assert_allclose(np.asarray(mjx_model.actuator_biasprm[:, 1]), [-3500] * 3 + [-3000] * 3)
    np.testing.assert_allclose(np.asarray(mjx_model.actuator_biasprm[:, 2]), 0.0)


def test_position_servos_variant_turns_the_base_at_force_limit_over_damping():
    """A 1 rad command to the base joint (vertical axis, no gravity torque) saturates the servo at 150 Nm, so the
    joint settles at 150 / 200 = 0.75 rad/s (hand-computed) long before it arrives."""
    model = fidelity.apply_variants(envs.make("ur5e-reach"), ["position_servos"]).robot.mj_model
    data = mujoco.MjData(model)
    data.qpos[:] = data.ctrl[:] = np.array([0.0, -1.57, 1.57, -1.57, -1.57, 0.0])
    data.ctrl[0] = 1.0
    for _ in range(150):  # 0.3 s: the base has turned about 0.2 rad, still saturated
        mujoco.mj_step(model, data)
    assert data.qvel[0] == pytest.approx(0.75, rel=0.02)


def test_training_with_variants_applies_them_to_every_ur5e_env_built(monkeypatch):
    monkeypatch.setattr(envs.registry, "build", envs.registry.build)  # restored after the test
    fidelity_train.patch_env_builders(["wrist_3=0"])
    made = envs.make("ur5e-reach")
    assert made.robot.geom_half[made.robot.mj_model.geom("wrist_3").id] == 0.0
    again = envs.from_config("ur5e-reach", envs.make_config("ur5e-reach"))
    assert again.robot.geom_half[again.robot.mj_model.geom("wrist_3").id] == 0.0
    driven = envs.registry.build("ur5e-reach", envs.make_config("ur5e-reach"))  # how the driver builds its env
    assert driven.robot.geom_half[driven.robot.mj_model.geom("wrist_3").id] == 0.0
    panda = envs.make("panda-reach")
    assert panda.robot.geom_half.tolist() == envs.robots.Panda().geom_half.tolist()  # left as built


@pytest.mark.parametrize("argv, named", [
    (["--variant", "wrist_3=0", "ur5e-reach-ppo"], "train.py's arguments follow `--`"),
    (["--variant", "wrist_3=0", "--", "panda-reach-ppo"], "env 'panda-reach' is not a UR5e env"),
    (["--variant", "wrist=0", "--", "ur5e-reach-ppo"], "--variant 'wrist=0' is unknown"),
])
def test_training_with_variants_refuses_bad_input_before_training(argv, named):
    with pytest.raises(ValueError, match=re.escape(named)):
        fidelity_train.main(argv)
