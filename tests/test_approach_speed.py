"""tools/approach_speed: the relative-control speed cap against a plain C MuJoCo loop over the same model."""

import datetime
import json
import shlex

import mujoco
import numpy as np

import envs
from agents import provenance
from tools import approach_speed


def test_the_json_names_what_made_it(tmp_path, monkeypatch):
    """--json holds the command, code, device and date (agents/provenance.py); the measurement is stubbed."""
    monkeypatch.delenv(provenance.COMMAND_VARIABLE, raising=False)
    monkeypatch.setattr(approach_speed, "servo_cap", lambda env: {"moving_step": [0.01] * 6,
                                                                   "moving_step_fraction_of_scale": [0.1] * 6})
    out = tmp_path / "speed.json"
    approach_speed.main(["--env", "ur5e-reach", "--json", str(out)])
    data = json.loads(out.read_text())
    assert data["command"] == shlex.join(["python", "-m", "tools.approach_speed", "--env", "ur5e-reach",
                                          "--json", str(out)])
    assert data["code"] == provenance.code_version()
    assert data["device"] == provenance.device_description()
    assert data["date"] == datetime.date.today().isoformat()


def test_full_step_moves_match_a_plain_mujoco_loop():
    config = envs.default_config("ur5e-reach")
    env = envs.from_config("ur5e-reach", config)
    moves, q0 = approach_speed.full_step_moves(env, num_envs=2, seed=3)
    assert moves.shape == (2, approach_speed.CAP_STEPS, 6)
    model = env.robot.mj_model
    data = mujoco.MjData(model)
    low, high = env.robot.joint_low, env.robot.joint_high
    for i in range(2):
        mujoco.mj_resetData(model, data)
        data.qpos[:] = q0[i]
        action = np.where(q0[i] < 0.5 * (low + high), 1.0, -1.0)
        expected = []
        for _ in range(approach_speed.CAP_STEPS):
            before = data.qpos.copy()
            data.ctrl[:] = np.clip(before + config.action_scale * action, low, high)
            for _ in range(config.substeps):
                mujoco.mj_step(model, data)
            expected.append(np.abs(data.qpos - before))
        np.testing.assert_allclose(moves[i], np.array(expected), atol=2e-4)
    # The servo's time constant, (kv + damping) / kp, is several env steps long: a joint covers only a fraction
    # of each commanded step.
    assert np.all(moves[:, -1] > 0.1 * config.action_scale)
    assert np.all(moves[:, -1] < 0.25 * config.action_scale)
