"""Reach and reach-avoid environments for the UR5e and the Franka Emika Panda, in MuJoCo MJX.

    import envs, jax
    env = envs.make("ur5e-reach")              # one environment, pure functions
    state = env.reset(jax.random.PRNGKey(0))
    state = env.step(state, jax.numpy.zeros(env.action_size))
    batched = envs.wrap(env)                     # episode limit, fresh auto-reset, vmap
"""

import contextlib as _contextlib
import io as _io

# mujoco.mjx probes for the optional Warp backend on import and prints when it is missing; we do
# not use Warp, so that probe's output is dropped (anything else it prints is passed on).
with _contextlib.redirect_stdout(_io.StringIO()) as _probe:
    from mujoco import mjx as _mjx  # noqa: F401
for _line in _probe.getvalue().splitlines():
    if not _line.startswith(("Failed to import warp", "Failed to import mujoco_warp")):
        print(_line)

from envs.base import Env, State  # noqa: E402
from envs.registry import EnvSpec, default_config, from_config, make, make_config, names, register  # noqa: E402
from envs.wrappers import wrap  # noqa: E402
from envs.config import ReachAvoidConfig, ReachConfig  # noqa: E402
from envs.point_mass import PointMass, PointMassConfig  # noqa: E402
from envs.robots import ROBOTS  # noqa: E402
from envs.robots.base import bounds as robot_bounds  # noqa: E402
from envs.tasks import Reach, ReachAvoid  # noqa: E402


def _arm_spec(robot: str, task: str) -> EnvSpec:
    config_cls, env_cls = (ReachConfig, Reach) if task == "reach" else (ReachAvoidConfig, ReachAvoid)

    def build(config):
        return env_cls(ROBOTS[robot](gravity_compensation=config.gravity_compensation, integrator=config.integrator), config)

    def check(config):
        config.validate_for_robot(robot, *robot_bounds(ROBOTS[robot]))

    return EnvSpec(config_cls, build, f"{ROBOTS[robot].__name__} {task}", robot=robot, check=check)


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
