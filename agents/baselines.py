"""The paper's reach baselines (section "Baselines"): random, standstill and pseudo inverse kinematics.

Each baseline is an `act(params, state, start, key)` for `agents.loop.make_evaluate` over a batched
arm environment. All three share one function, the baseline being picked by `params` (its index in
`BASELINES`, a traced int), so one compiled evaluation serves every baseline of an env config.

Two of them are defined by a joint configuration to command, which maps onto the env's action mode
(`ReachConfig.action`, see `joint_target_action`):

- `random`: uniform actions in [-1, 1] every step, in the env's own action space. The behaviour
  depends strongly on the mode: with `absolute` control every step commands a uniformly random
  configuration of the full joint range (the arm flails around the range's middle); with
  `relative` control it is a random walk of at most one relative step (`relative_step`) per joint
  around the initial pose. The paper's random agent is absolute control's (results: baselines study). On the Panda
  absolute control is the safer mode: the middle of its narrow ranges is a safe pose, while a
  random walk runs into its joint limits.
- `standstill`: commands the episode's initial pose ("uses its initial pose as the action").
  absolute: that pose's action; relative: the step back to it, (q0 - q) / relative_step, clipped, so
  the position servo's target is q0 in both modes. The zero relative action is *not* a standstill:
  it re-targets the sagged pose every step, so gravity pulls the arm down step by step.
- `pseudo_ik`: commands `info["target_qpos"]`, the configuration whose forward kinematics produced
  the target (so it is known to reach it), the same way; only defined for target_sampling =
  "reachable". Relative control moves the servo target by at most `relative_step` per step
  towards it and the arm creeps after it, while absolute control jumps. It fails by
  self-collision on the way (joint-space path) and by the servos' steady-state error under
  gravity (the end effector settles off the target).

`standstill` reads the first episode's initial pose from `start`: only the first episode of each
env is valid (which is all `make_evaluate` counts).
"""

from __future__ import annotations

import jax
import jax.numpy as jnp
import numpy as np

BASELINES = ("random", "standstill", "pseudo_ik")


def check(name: str, env) -> None:
    """ValueError if `name` is no baseline or cannot run on `env` (the unwrapped env is looked up)."""
    if name not in BASELINES:
        raise ValueError(f"policy={name!r} is unknown: allowed are {', '.join(BASELINES)}.")
    base = env.unwrapped
    config = getattr(base, "config", None)
    if name == "pseudo_ik":
        if not hasattr(base, "robot"):
            raise ValueError(f"policy='pseudo_ik' needs an arm environment (its target's joint configuration); "
                             f"{type(base).__name__} has none: allowed are random, standstill.")
        if config.target_sampling != "reachable":
            raise ValueError(f"policy='pseudo_ik' is undefined with target_sampling={config.target_sampling!r}: "
                             "a uniformly sampled target has no known joint configuration; allowed is "
                             "target_sampling='reachable'.")


def joint_target_action(config, robot, target, base):
    """The action that sets the position servos' target to joint configuration `target` (as far as
    one step allows in relative mode), inverting `ArmEnv.action_to_ctrl`; `base` is what a relative
    delta is added to (the joint positions, or the last targets with `relative_to="target"`)."""
    low, high = robot.joint_low, robot.joint_high
    if config.action == "absolute":
        action = 2.0 * (target - low) / (high - low) - 1.0
    else:
        action = (target - base) / config.relative_step(low, high)
    return jnp.clip(action, -1.0, 1.0)


def make_act(env):
    """`act(index, state, start, key)` over batched states: the baseline `BASELINES[index]`."""
    base = env.unwrapped
    action_size = env.action_size
    robot = getattr(base, "robot", None)

    def act(index, state, start, key):
        shape = state.obs.shape[:-1] + (action_size,)
        random = jax.random.uniform(key, shape, minval=-1.0, maxval=1.0)
        if robot is None:  # probe tasks (point mass): velocity control, 0 stands still
            return jnp.where(index == 0, random, jnp.zeros(shape))
        data = state.pipeline_state
        delta_base = data.ctrl if base.config.relative_to == "target" else data.qpos
        still = joint_target_action(base.config, robot, start.pipeline_state.qpos, delta_base)
        ik = joint_target_action(base.config, robot, state.info["target_qpos"], delta_base)
        return jnp.select([index == 0, index == 1], [random, still], ik)

    return act


def index(name: str) -> np.int32:
    """The `params` of `make_act`'s function for baseline `name`."""
    if name not in BASELINES:
        raise ValueError(f"policy={name!r} is unknown: allowed are {', '.join(BASELINES)}.")
    return np.int32(BASELINES.index(name))
