"""Reach and reach-avoid environments for the UR5e and the Franka Emika Panda, in MuJoCo MJX.

    import envs, jax
    env = envs.make("ur5e-reach")              # one environment, pure functions
    state = env.reset(jax.random.PRNGKey(0))
    state = env.step(state, jax.numpy.zeros(env.action_size))
    batched = envs.wrap(env)                     # episode limit, fresh auto-reset, vmap
"""

from envs.base import Env, State
from envs.registry import EnvSpec, default_config, from_config, make, make_config, names, register
from envs.wrappers import wrap
from envs.config import ReachAvoidConfig, ReachConfig
from envs.point_mass import PointMass, PointMassConfig
from envs.robots import ROBOTS
from envs.tasks import Reach, ReachAvoid


def _arm_spec(robot: str, task: str) -> EnvSpec:
    config_cls, env_cls = (ReachConfig, Reach) if task == "reach" else (ReachAvoidConfig, ReachAvoid)

    def build(config):
        return env_cls(ROBOTS[robot](gravity_compensation=config.gravity_compensation), config)

    return EnvSpec(config_cls, build, f"{ROBOTS[robot].__name__} {task}")


for _robot in ROBOTS:
    for _task in ("reach", "reach-avoid"):
        register(f"{_robot}-{_task}", _arm_spec(_robot, _task))
register(
    "point-mass",
    EnvSpec(PointMassConfig, PointMass, "pure-JAX point mass reaching a goal (probe task for learners)"),
)

__all__ = [
    "Env", "EnvSpec", "State", "default_config", "from_config", "make", "make_config", "names",
    "register", "wrap", "PointMass", "PointMassConfig", "Reach", "ReachAvoid", "ReachConfig",
    "ReachAvoidConfig",
]
