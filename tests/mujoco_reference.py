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


def obstacles_model(robot, radii, every_geom: bool = False):
    """`contact_model` with one obstacle sphere per entry of `radii`: the MJCF's `obstacle` and copies
    of it (`obstacle1`, ...), each in the same `<pair>`s with the robot geoms as the original; with
    `every_geom`, paired with every robot geom (what a moving obstacle is checked against)."""
    from envs.robots.base import ASSETS
    spec = mujoco.MjSpec.from_file(str(ASSETS / robot.xml_file))
    partners = [p.geomname1 if p.geomname2 == "obstacle" else p.geomname2 for p in spec.pairs
                if "obstacle" in (p.geomname1, p.geomname2)]
    if every_geom:
        unpaired = [robot.mj_model.geom(int(g)).name for g in robot.robot_geoms]
        unpaired = [name for name in unpaired if name not in partners]
        for geom in unpaired:
            spec.add_pair(geomname1=geom, geomname2="obstacle")
        partners += unpaired
    for j in range(1, len(radii)):
        body = spec.worldbody.add_body(name=f"obstacle{j}", mocap=True, pos=[0.5, 0, -5])
        body.add_geom(name=f"obstacle{j}", type=mujoco.mjtGeom.mjGEOM_SPHERE, size=[radii[j], 0, 0], contype=0,
                      conaffinity=0)
        for geom in partners:
            spec.add_pair(geomname1=geom, geomname2=f"obstacle{j}")
    # Sized before compiling: mj_collision skips a pair whose bounding spheres (from the compiled sizes) miss.
    spec.geom("obstacle").size = [radii[0], 0, 0]
    model = spec.compile()
    model.opt.disableflags &= ~int(mujoco.mjtDisableBit.mjDSBL_CONTACT)
    return model


def obstacle_contacts(model, qpos, centers):
    """(set of (obstacle index, robot geom) pairs penetrating by `mj_collision`, signed distances
    [n obstacles, robot geoms of the pairs] by `mj_geomDistance`, those robot geoms) at `qpos` with
    the obstacles of `obstacles_model` at `centers`."""
    data = mujoco.MjData(model)
    data.qpos[:] = qpos
    geoms = [model.geom("obstacle").id] + [model.geom(f"obstacle{j}").id for j in range(1, len(centers))]
    for geom, center in zip(geoms, centers):
        data.mocap_pos[model.body_mocapid[model.geom_bodyid[geom]]] = center
    mujoco.mj_kinematics(model, data)
    mujoco.mj_collision(model, data)
    contacts = set()
    for c in data.contact[: data.ncon]:
        if c.dist < 0:
            for j, geom in enumerate(geoms):
                if geom in (c.geom1, c.geom2):
                    contacts.add((j, int(c.geom2 if c.geom1 == geom else c.geom1)))
    robot_geoms = sorted({int(g2 if g1 == geoms[0] else g1) for g1, g2 in zip(model.pair_geom1, model.pair_geom2)
                          if geoms[0] in (g1, g2)})
    distances = np.array([[mujoco.mj_geomDistance(model, data, g, r, 10.0, None) for r in robot_geoms] for g in geoms])
    return contacts, distances, robot_geoms
