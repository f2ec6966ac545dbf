"""The paper's learner-free baselines (agents/baselines.py) through eval.py: one compiled evaluation serves all
three, the baseline being a traced index.
"""

import datetime
import json

import jax
import jax.numpy as jnp
import numpy as np
import pytest

import envs
import eval as eval_cli
from agents import baselines


BASELINE_ENV = dict(action="absolute", episode_length=100, target_radius=0.02)
"""Absolute control (the paper's baselines, see eval.py) and 100 steps (4 s): the random agent's
collisions come early (median step 20 at 4096 envs), the pseudo-IK needs ~80 steps on average to
swing its joints (up to 4 pi rad at ~pi rad/s) to the target's pose."""


BASELINE_ARGS = ["--env", "ur5e-reach", "--num-envs", "16"] + [f"--env.{k.replace('_', '-')}={v}" for k, v in BASELINE_ENV.items()]


@pytest.fixture(scope="module")
def baseline_runs(tmp_path_factory):
    """eval.py (in process) for each baseline: {name: (result, json path, csv path)}."""
    out = tmp_path_factory.mktemp("baselines")
    runs = {}
    for name in baselines.BASELINES:
        paths = (out / f"{name}.json", out / f"{name}.csv")
        [result] = eval_cli.main(BASELINE_ARGS + ["--policy", name, "--json", str(paths[0]), "--csv", str(paths[1])])
        runs[name] = (result, *paths)
    return runs


@pytest.fixture(scope="module")
def baseline_results(baseline_runs):
    return {name: run[0] for name, run in baseline_runs.items()}


def test_baselines_behave_as_in_the_paper(baseline_results):
    s = {name: r.summary() for name, r in baseline_results.items()}
    # Standstill: holds its initial pose, never reaches, never collides.
    assert s["standstill"]["target_reached"]["mean"] == 0
    assert s["standstill"]["self_collision"]["mean"] == 0
    assert s["standstill"]["steps_in_target"]["mean"] == 0
    # Random (absolute control): flails and self-collides often (paper 30 %, ours 22 % at 4096 envs).
    assert s["random"]["target_reached"]["mean"] == 0
    assert s["random"]["self_collision"]["mean"] >= 2 / 16
    # Pseudo-IK: commands the target's own pose; a fair share reaches, the rest collides on the way
    # or settles off target under gravity; far closer than standing still.
    assert s["pseudo_ik"]["target_reached"]["mean"] >= 3 / 16
    assert s["pseudo_ik"]["distance_not_collided"]["mean"] < 0.5 * s["standstill"]["distance"]["mean"]
    assert s["pseudo_ik"]["steps_in_target"]["mean"] > 0
    # Same episodes for every baseline (one evaluation seed): same initial distances.
    assert baseline_results["random"].eval_seeds == baseline_results["standstill"].eval_seeds


def test_baseline_actions_command_the_right_joint_targets():
    """standstill / pseudo-IK actions invert the env's action mapping in both modes."""
    for action in ("absolute", "relative"):
        env = envs.wrap(envs.make("ur5e-reach", action=action))
        base = env.unwrapped
        robot = base.robot
        rng = np.random.default_rng(0)
        q = rng.uniform(robot.joint_low, robot.joint_high, (5, 6)).astype(np.float32)
        near = np.clip(q + rng.uniform(-0.05, 0.05, q.shape), robot.joint_low, robot.joint_high).astype(np.float32)
        a = baselines.joint_target_action(base.config, robot, jnp.asarray(near), jnp.asarray(q))
        np.testing.assert_allclose(base.action_to_ctrl(a, jnp.asarray(q)), near, atol=2e-5)
        far = q + 1.0  # relative control: one step of at most action_scale towards it
        a = baselines.joint_target_action(base.config, robot, jnp.asarray(far), jnp.asarray(q))
        if action == "relative":
            np.testing.assert_allclose(a, 1.0)


def test_pseudo_ik_with_relative_to_target_commands_the_target_pose():
    """relative_to="target": pseudo-IK's deltas are taken from the last targets, so its commanded targets
    reach the target pose exactly after ceil(max |target - start| / action_scale) steps and stay there."""
    env = envs.wrap(envs.make("ur5e-reach", backend="mujoco", relative_to="target", action_scale=0.5), autoreset=False)
    act, step = jax.jit(baselines.make_act(env)), jax.jit(env.step)
    start = state = jax.jit(env.reset)(jax.random.split(jax.random.PRNGKey(2), 2))  # jitted: one step program
    needed = int(np.ceil(np.abs(np.asarray(start.info["target_qpos"] - start.pipeline_state.qpos)).max() / 0.5))
    for t in range(needed + 1):
        before = state.pipeline_state.ctrl
        state = step(state, act(baselines.index("pseudo_ik"), state, start, jax.random.PRNGKey(t)))
        if t == needed - 1:
            assert np.abs(np.asarray(before - start.info["target_qpos"])).max() > 1e-4  # not there a step early
    np.testing.assert_allclose(state.pipeline_state.ctrl, start.info["target_qpos"], atol=1e-5)


def test_cli_baseline_json_csv(baseline_runs):
    """The contract `eval.py --env ur5e-reach --policy standstill --num-envs N --json out.json`."""
    result, out, table = baseline_runs["standstill"]
    report = json.loads(out.read_text())
    ev = report["evaluations"][0]
    assert report["env_name"] == "ur5e-reach"
    assert report["num_envs"] == 16
    assert report["eval_seeds"] == [1_000_000]
    assert report["command"].startswith("python eval.py --env ur5e-reach --num-envs 16")
    assert report["date"] == datetime.date.today().isoformat()  # with command, code, device: agents/provenance.py
    assert ev["policy"] == {"kind": "baseline", "name": "standstill"}
    assert ev["env_config"]["action"] == "absolute"
    assert ev["env_config"]["episode_length"] == 100
    assert ev["env_config"]["substeps"] == 20  # untouched fields: the env's defaults
    assert set(ev["summary"]) >= {"target_reached", "self_collision", "obstacle_collision", "distance",
                                  "steps_in_target", "times_left_target"}
    assert ev["summary"]["distance"]["mean"] == pytest.approx(result.summary()["distance"]["mean"])
    assert len(ev["units"]) == 1
    assert ev["units"][0]["metrics"]["target_reached"] == 0
    wall = report["wall_seconds"]  # where the process's time went
    assert wall["evaluations"] == pytest.approx(ev["seconds"], abs=0.01)
    assert wall["before_evaluations"] + wall["evaluations"] <= wall["total"] + 0.01
    rows = table.read_text().splitlines()
    assert len(rows) == 2
    assert "target_reached" in rows[0]
    assert rows[1].startswith("standstill,ur5e-reach,")
