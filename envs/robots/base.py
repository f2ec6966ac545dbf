"""The abstract robot: its model, joint ranges, kinematics, collision geometry and pose sampling.

A robot is data (an MJCF file in `assets/`, official limits) plus shared logic. Everything the
collision checks need is read from the MJCF: the radius and half-length of each capsule/sphere
geom, and the explicit `<contact><pair>` list, which names the self-collision pairs and, through
the `obstacle` geom, the robot geoms that can touch an obstacle.
"""

from __future__ import annotations

import abc
import functools
import threading
from pathlib import Path
from typing import NamedTuple

import jax
import jax.numpy as jnp
import mujoco
import numpy as np
from mujoco import mjx

from envs import collision

ASSETS = Path(__file__).resolve().parents[2] / "assets"
# `ReachConfig.integrator` -> MuJoCo's enum.
INTEGRATORS = {"implicitfast": mujoco.mjtIntegrator.mjINT_IMPLICITFAST, "euler": mujoco.mjtIntegrator.mjINT_EULER}


class Kinematics(NamedTuple):
    """Forward kinematics of one or more joint configurations (leading batch axes allowed)."""

    xpos: jax.Array
    """Body frame origins, `[..., nbody, 3]`."""
    geom_xpos: jax.Array
    """Geom centres, `[..., ngeom, 3]`."""
    geom_xmat: jax.Array
    """Geom orientations, `[..., ngeom, 3, 3]`."""
    site_xpos: jax.Array
    """Site positions, `[..., nsite, 3]`."""
    ee_pos: jax.Array
    """End-effector site position, `[..., 3]`."""


_SHARED: dict = {}
"""(robot class, gravity compensation, integrator, JAX backend) -> (mjx_model, data_template) of a robot as built."""
_SHARED_LOCK = threading.Lock()


@functools.lru_cache(maxsize=None)
def bounds(robot_cls: type) -> tuple[float, float]:
    """(reach, widest joint range in rad) of a robot class, for config checks before an env is built
    (the robot is built once per process)."""
    robot = robot_cls()
    return float(robot.reach), float(np.max(robot.joint_high - robot.joint_low))


class Robot(abc.ABC):
    """Shared robot logic. Subclasses name the MJCF file and give the official limits."""

    name: str = ""
    """Short name used in environment names (`ur5e`, `panda`)."""
    xml_file: str = ""
    """MJCF file name inside `assets/`."""

    @property
    @abc.abstractmethod
    def velocity_limits(self) -> np.ndarray:
        """Official joint velocity limits (rad/s), one per joint."""

    @property
    @abc.abstractmethod
    def reach(self) -> float:
        """Maximum distance (m) from `workspace_center` to the end effector over the joint range:
        the radius of the `full` workspace and the paper's d_max."""

    @abc.abstractmethod
    def limited_range(self) -> tuple[np.ndarray, np.ndarray]:
        """The reduced joint range of `init_range="limited"` initial poses, (low, high)."""

    def __init__(self, gravity_compensation: bool = False, integrator: str = "model"):
        spec = mujoco.MjSpec.from_file(str(ASSETS / self.xml_file))
        if integrator != "model":
            spec.option.integrator = INTEGRATORS[integrator]
        if gravity_compensation:
            # Passive gravity compensation of every robot body, as the real arms' controllers do.
            for body in spec.bodies:
                if not body.mocap:
                    body.gravcomp = 1.0
        model = spec.compile()
        self.mj_model = model
        self.gravity_compensation = gravity_compensation
        self.nq = model.nq
        self.joint_low = model.jnt_range[:, 0].astype(np.float32)
        self.joint_high = model.jnt_range[:, 1].astype(np.float32)
        self.ee_site = model.site("ee").id
        self.target_mocap = model.body_mocapid[model.body("target").id]
        self.obstacle_mocap = model.body_mocapid[model.body("obstacle").id]
        obstacle_geom = model.geom("obstacle").id

        # Collision geometry: capsules lie along local z with size (radius, half-length);
        # spheres are capsules of zero length.
        self.geom_radius = model.geom_size[:, 0].astype(np.float32)
        capsule = model.geom_type == mujoco.mjtGeom.mjGEOM_CAPSULE
        self.geom_half = np.where(capsule, model.geom_size[:, 1], 0.0).astype(np.float32)
        robot_geom = model.body_mocapid[model.geom_bodyid] < 0
        self.robot_geoms = np.flatnonzero(robot_geom)

        pairs = np.stack([model.pair_geom1, model.pair_geom2], axis=1)
        with_obstacle = np.any(pairs == obstacle_geom, axis=1)
        self.self_pairs = pairs[~with_obstacle]
        self.obstacle_geoms = np.sort(np.where(pairs[with_obstacle, 0] == obstacle_geom,
                                               pairs[with_obstacle, 1], pairs[with_obstacle, 0]))
        # The model's obstacle pairs leave out the geoms no joint moves (the base; the first link, which only spins
        # about its own axis): a static obstacle sampled clear of them never touches them, a moving one can.
        self.fixed_geoms = np.setdiff1d(self.robot_geoms, self.obstacle_geoms)
        # Links for the paper's link-to-obstacle distances: the bodies that can touch an obstacle.
        self.link_bodies = np.unique(model.geom_bodyid[self.obstacle_geoms])
        self.link_geom_body = np.searchsorted(self.link_bodies, model.geom_bodyid[self.obstacle_geoms])

        # Centre of the workspace: the second joint's anchor projected onto the base axis.
        data = mujoco.MjData(model)
        mujoco.mj_kinematics(model, data)
        self.workspace_center = np.array([0.0, 0.0, data.xanchor[1, 2]], np.float32)

        self.integrator = integrator
        # The MJX model is put on the device when first used (`_on_device`): a robot made only to check a config
        # never pays for the transfer, and robots built alike share one copy.
        self._device: tuple | None = None

    @property
    def mjx_model(self) -> mjx.Model:
        """The MJX model of `mj_model`, on the default device."""
        return self._on_device()[0]

    @property
    def data_template(self) -> mjx.Data:
        """An empty `mjx.Data` of `mjx_model`, which `reset` fills in."""
        return self._on_device()[1]

    def _on_device(self) -> tuple:
        """(mjx_model, data_template): this robot's own after `put_on_device`, else the one shared by the robots of
        its class, gravity compensation and integrator, put once a process from a freshly built robot (so an
        in-place edit of this robot's `mj_model` reaches MJX through `put_on_device` only, never the shared copy)."""
        if self._device is not None:
            return self._device
        with _SHARED_LOCK:  # programs may be traced in threads (agents.ahead.Ahead)
            key = (type(self), self.gravity_compensation, self.integrator, jax.default_backend())
            if key not in _SHARED:
                fresh = type(self)(gravity_compensation=self.gravity_compensation, integrator=self.integrator)
                fresh.put_on_device()
                _SHARED[key] = fresh._device
            self._device = _SHARED[key]
            return self._device

    def put_on_device(self) -> None:
        """Builds `mjx_model` and `data_template` from `mj_model`: on first use, and again after `mj_model` is edited
        in place (an experiment's variant), so that MJX steps the edited model. Concrete arrays even when first asked
        for inside a trace, so jitted functions close over constants."""
        with jax.ensure_compile_time_eval():
            model = mjx.put_model(self.mj_model)
            self._device = (model, mjx.make_data(model))

    # ----------------------------------------------------------------------------------------
    # Kinematics and collision geometry (pure JAX)

    def kinematics(self, qpos: jax.Array) -> Kinematics:
        """Forward kinematics of joint configurations `qpos` `[..., nq]`, in world coordinates.

        A product of 3x3 rotations down the serial chain, with the model's own constants (body
        offsets, joint axes and anchors): the same result as `mjx.kinematics` (tested against CPU
        MuJoCo), at a fraction of its cost, which matters because every reset evaluates it for
        dozens of candidate poses.
        """
        k = self._chain
        batch = qpos.shape[:-1]
        xpos = [jnp.broadcast_to(jnp.zeros(3), batch + (3,))]
        xmat = [jnp.broadcast_to(jnp.eye(3), batch + (3, 3))]
        for body in range(1, k["nbody"]):
            parent = k["parent"][body]
            pos = xpos[parent] + jnp.einsum("...ij,j->...i", xmat[parent], k["body_pos"][body])
            rot = jnp.einsum("...ij,jk->...ik", xmat[parent], k["body_mat"][body])
            joint = k["joint"][body]
            if k["mocap"][body]:
                pos, rot = jnp.broadcast_to(k["body_pos"][body], batch + (3,)), jnp.broadcast_to(jnp.eye(3), batch + (3, 3))
            elif joint >= 0:
                # Hinge: rotate about the joint axis through the joint anchor (both in body frame).
                anchor = pos + jnp.einsum("...ij,j->...i", rot, k["jnt_pos"][joint])
                rot = jnp.einsum("...ij,...jk->...ik", rot, _axis_angle(k["jnt_axis"][joint], qpos[..., joint]))
                pos = anchor - jnp.einsum("...ij,j->...i", rot, k["jnt_pos"][joint])
            xpos.append(pos)
            xmat.append(rot)
        xpos, xmat = jnp.stack(xpos, axis=-2), jnp.stack(xmat, axis=-3)
        gb, sb = k["geom_body"], k["site_body"]
        geom_xpos = xpos[..., gb, :] + jnp.einsum("...gij,gj->...gi", xmat[..., gb, :, :], k["geom_pos"])
        geom_xmat = jnp.einsum("...gij,gjk->...gik", xmat[..., gb, :, :], k["geom_mat"])
        site_xpos = xpos[..., sb, :] + jnp.einsum("...sij,sj->...si", xmat[..., sb, :, :], k["site_pos"])
        return Kinematics(xpos, geom_xpos, geom_xmat, site_xpos, site_xpos[..., self.ee_site, :])

    @functools.cached_property
    def _chain(self) -> dict:
        """Model constants for `kinematics` (numpy, so they fold into compiled code)."""
        m = self.mj_model

        def mats(quats):
            out = np.zeros((len(quats), 9))
            for i, q in enumerate(quats):
                mujoco.mju_quat2Mat(out[i], q)
            return out.reshape(-1, 3, 3).astype(np.float32)

        joint = np.full(m.nbody, -1)
        for j in range(m.njnt):
            if m.jnt_type[j] != mujoco.mjtJoint.mjJNT_HINGE or np.count_nonzero(m.jnt_bodyid == m.jnt_bodyid[j]) > 1:
                raise ValueError(f"{self.name}: kinematics supports one hinge joint per body; joint {j} is not.")
            joint[m.jnt_bodyid[j]] = j
        if not np.array_equal(m.jnt_qposadr, np.arange(m.njnt)) or np.any(m.qpos0 != 0):
            raise ValueError(f"{self.name}: kinematics expects qpos[i] to be joint i with zero reference.")
        return {
            "nbody": m.nbody, "parent": m.body_parentid, "joint": joint, "mocap": m.body_mocapid >= 0,
            "body_pos": m.body_pos.astype(np.float32), "body_mat": mats(m.body_quat),
            "jnt_pos": m.jnt_pos.astype(np.float32), "jnt_axis": m.jnt_axis.astype(np.float32),
            "geom_body": m.geom_bodyid, "geom_pos": m.geom_pos.astype(np.float32), "geom_mat": mats(m.geom_quat),
            "site_body": m.site_bodyid, "site_pos": m.site_pos.astype(np.float32),
        }

    def self_distances(self, geom_xpos: jax.Array, geom_xmat: jax.Array) -> jax.Array:
        """Signed distances of the self-collision pairs, `[..., npairs]`; < 0 is a collision."""
        return collision.pair_distances(geom_xpos, geom_xmat, self.geom_radius, self.geom_half,
                                        self.self_pairs[:, 0], self.self_pairs[:, 1])

    def obstacle_distances(self, geom_xpos, geom_xmat, center, radius, geoms=None) -> jax.Array:
        """Signed distances between a sphere obstacle and robot geoms (default: the ones that
        can touch it), `[..., ngeoms]`; < 0 is a collision."""
        geoms = self.obstacle_geoms if geoms is None else geoms
        return collision.sphere_distances(center, radius, geom_xpos, geom_xmat, self.geom_radius,
                                          self.geom_half, geoms)

    def link_obstacle_distances(self, kin_xpos, geom_xpos, geom_xmat, center, radius, mode):
        """Distance of each link (`link_bodies`) to the obstacle surface, `[..., nlinks]`.

        `mode="origin"` is the paper's d_i = |p_link,i - p_obst| - s_obst with p_link the link's
        frame origin; `mode="surface"` is the exact signed distance of the link's capsules.
        """
        if mode == "origin":
            return jnp.linalg.norm(self.link_positions(kin_xpos) - center[..., None, :], axis=-1) - radius
        per_geom = self.obstacle_distances(geom_xpos, geom_xmat, center, radius)
        nlinks = len(self.link_bodies)
        onehot = self.link_geom_body[:, None] == np.arange(nlinks)[None, :]
        return jnp.min(jnp.where(onehot, per_geom[..., :, None], jnp.inf), axis=-2)

    # ----------------------------------------------------------------------------------------
    # Sampling (pure JAX)

    def joint_range(self, init_range: str) -> tuple[np.ndarray, np.ndarray]:
        """(low, high) of `"full"` (the model's joint range) or `"limited"` initial poses."""
        if init_range == "full":
            return self.joint_low, self.joint_high
        low, high = self.limited_range()
        return np.asarray(low, np.float32), np.asarray(high, np.float32)

    def sample_poses(self, key, num, low, high):
        """`num` joint configurations uniform in [low, high], their kinematics and a validity
        mask (collision free)."""
        qpos = jax.random.uniform(key, (num, self.nq), minval=low, maxval=high)
        kin = self.kinematics(qpos)
        free = jnp.all(self.self_distances(kin.geom_xpos, kin.geom_xmat) > 0.0, axis=-1)
        return qpos, kin, free

    def sample_reachable(self, key, num):
        """`num` candidate targets that the end effector reaches: (positions, the joint
        configurations reaching them, collision-free mask). Poses are uniform over the full joint
        range, so the positions are not uniform in space (paper, "Initial pose and target
        sampling")."""
        qpos, kin, free = self.sample_poses(key, num, self.joint_low, self.joint_high)
        return kin.ee_pos, qpos, free

    def link_positions(self, xpos: jax.Array) -> jax.Array:
        """Frame origins of the links that can touch an obstacle, `[..., nlinks, 3]`."""
        return xpos[..., self.link_bodies, :]


def _axis_angle(axis: np.ndarray, angle: jax.Array) -> jax.Array:
    """Rotation matrices `[..., 3, 3]` about unit `axis` by `angle` (Rodrigues' formula)."""
    x, y, z = (float(a) for a in axis)
    skew = np.array([[0, -z, y], [z, 0, -x], [-y, x, 0]], np.float32)
    sin, cos = jnp.sin(angle)[..., None, None], jnp.cos(angle)[..., None, None]
    return np.eye(3, dtype=np.float32) + sin * skew + (1 - cos) * (skew @ skew)


def first_valid(valid: jax.Array) -> tuple[jax.Array, jax.Array]:
    """Index of the first True entry of `valid` along its last axis (0 if none) and whether one exists.

    Rejection sampling with a fixed number of candidates: under `vmap` a `while_loop` runs until
    the unluckiest environment is done, a fixed candidate batch does not.
    """
    return jnp.argmax(valid, axis=-1), jnp.any(valid, axis=-1)
