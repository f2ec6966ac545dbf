"""The reach task: bring the end effector into the target and keep it there."""

from envs.arm import ArmEnv


class Reach(ArmEnv):
    """Reach in free space; the only failure is a self-collision. All logic is in `ArmEnv`."""
