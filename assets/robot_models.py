"""The robot models of assets/ as assets/derive.py and assets/collision_pairs.py load and sample them (CPU MuJoCo)."""
from __future__ import annotations

import pathlib

import mujoco
import numpy as np

HERE = pathlib.Path(__file__).resolve().parent


def xml_path(robot: str) -> pathlib.Path:
    return HERE / f"{robot}.xml"


def load(robot: str, gravcomp: bool = False) -> mujoco.MjModel:
    """The robot's model; `gravcomp`: every robot body gets gravcomp = 1 (as envs/ can request)."""
    spec = mujoco.MjSpec.from_file(str(xml_path(robot)))
    if gravcomp:
        for body in spec.bodies:
            if not body.mocap:
                body.gravcomp = 1.0
    return spec.compile()


def joint_limits(m: mujoco.MjModel) -> tuple[np.ndarray, np.ndarray]:
    return m.jnt_range[:, 0].copy(), m.jnt_range[:, 1].copy()


def sample_q(m: mujoco.MjModel, rng: np.random.Generator, n: int) -> np.ndarray:
    lo, hi = joint_limits(m)
    return rng.uniform(lo, hi, size=(n, m.nq))
