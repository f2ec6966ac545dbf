"""Universal Robots UR5e (model: `assets/ur5e.xml`)."""

import numpy as np

from envs.robots.base import Robot


class UR5e(Robot):
    """6-DoF UR5e. Joint ranges +-2 pi (elbow +-pi); official speed limit pi rad/s per joint."""

    name = "ur5e"
    xml_file = "ur5e.xml"
    VELOCITY_LIMITS = (np.pi,) * 6
    """Official joint velocity limits (rad/s): UR5e user manual, 180 deg/s on every joint (assets/derive.py reads
    them without building the robot)."""

    @property
    def velocity_limits(self) -> np.ndarray:
        return np.array(self.VELOCITY_LIMITS, np.float32)

    @property
    def reach(self) -> float:
        # Largest shoulder-point-to-flange distance over 300k random poses is 0.969 m
        # (`python assets/derive.py ur5e`); the datasheet's 850 mm is measured differently.
        return 0.97

    def limited_range(self):
        # The paper's "limited" initialisation: 360 instead of 720 degrees per joint.
        return np.maximum(self.joint_low, -np.pi), np.minimum(self.joint_high, np.pi)
