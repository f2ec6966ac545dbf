"""Tasks: reach and reach-avoid."""

from envs.tasks.reach import Reach
from envs.tasks.reach_avoid import ReachAvoid

__all__ = ["Reach", "ReachAvoid"]
