"""Franka Emika Panda (model: `assets/panda.xml`)."""

import numpy as np

from envs.robots.base import Robot


class Panda(Robot):
    """7-DoF Franka Emika Panda with official joint and velocity limits."""

    name = "panda"
    xml_file = "panda.xml"
    VELOCITY_LIMITS = (2.175,) * 4 + (2.61,) * 3
    """Official joint velocity limits (rad/s): Franka documentation, control parameters of the Panda (assets/derive.py
    reads them without building the robot)."""

    @property
    def velocity_limits(self) -> np.ndarray:
        return np.array(self.VELOCITY_LIMITS, np.float32)

    @property
    def reach(self) -> float:
        # Largest shoulder-point-to-gripper distance over 300k random poses is 0.944 m
        # (`python assets/derive.py panda`); the datasheet says 855 mm, measured differently.
        return 0.945

    def limited_range(self):
        # Not from the paper (its Panda ranges are all below 360 degrees): the middle half of
        # each joint's range, the analogue of halving the UR5e's range.
        mid, half = (self.joint_low + self.joint_high) / 2, (self.joint_high - self.joint_low) / 4
        return mid - half, mid + half
