"""Independent references computed with CPU MuJoCo (not MJX, not our JAX code)."""

import mujoco
import numpy as np


def contact_model(robot, obstacle_radius=None):
    """A copy of the robot's MjModel with contacts enabled, so `mj_collision` evaluates exactly the
    explicit `<pair>` list that our analytic checks use."""
    from envs.robots.base import ASSETS
    model = mujoco.MjModel.from_xml_path(str(ASSETS / robot.xml_file))
    model.opt.disableflags &= ~int(mujoco.mjtDisableBit.mjDSBL_CONTACT)
    if obstacle_radius is not None:
        model.geom_size[model.geom("obstacle").id, 0] = obstacle_radius
    return model


def colliding_pairs(model, qpos, obstacle_pos=None):
    """Set of (geom1, geom2) pairs in contact (penetrating) at `qpos`, by `mj_collision`."""
    data = mujoco.MjData(model)
    data.qpos[:] = qpos
    if obstacle_pos is not None:
        data.mocap_pos[model.body_mocapid[model.body("obstacle").id]] = obstacle_pos
    mujoco.mj_kinematics(model, data)
    mujoco.mj_collision(model, data)
    return {tuple(sorted((int(c.geom1), int(c.geom2)))) for c in data.contact[: data.ncon] if c.dist < 0}


def ee_position(model, qpos):
    """World position of the `ee` site at `qpos` (CPU forward kinematics)."""
    data = mujoco.MjData(model)
    data.qpos[:] = qpos
    mujoco.mj_kinematics(model, data)
    return data.site_xpos[model.site("ee").id].copy()


def geom_poses(model, qpos):
    """(geom_xpos, geom_xmat as 3x3) at `qpos`, from CPU MuJoCo."""
    data = mujoco.MjData(model)
    data.qpos[:] = qpos
    mujoco.mj_kinematics(model, data)
    return data.geom_xpos.copy(), data.geom_xmat.reshape(-1, 3, 3).copy()


def colliding_configuration(robot, seed):
    """A joint configuration drawn uniformly within the joint limits that CPU MuJoCo finds in
    self-collision (the first such draw of `seed`)."""
    rng = np.random.default_rng(seed)
    model = contact_model(robot)
    while True:
        q = rng.uniform(robot.joint_low, robot.joint_high).astype(np.float32)
        if colliding_pairs(model, q):
            return q
