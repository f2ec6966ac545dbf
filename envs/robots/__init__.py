"""Robots: the abstract `Robot` and the UR5e and Panda."""

from envs.robots.base import Kinematics, Robot, first_valid
from envs.robots.panda import Panda
from envs.robots.ur5e import UR5e

ROBOTS = {"ur5e": UR5e, "panda": Panda}

__all__ = ["Kinematics", "Robot", "first_valid", "Panda", "UR5e", "ROBOTS"]
