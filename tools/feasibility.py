"""Which episodes an arm could finish at all: a learner-free upper bound on the reached rate of a task.

    python -m tools.feasibility ur5e-reach-avoid --episodes 4096
    python -m tools.feasibility panda-reach-avoid --episodes 4096 --json feasibility.json
    python -m tools.feasibility ur5e-reach-avoid --option obstacle_radius=0.15

An episode is feasible when some joint configuration within the joint ranges puts the end effector in the target
(closer than `target_radius`) with no collision (no negative signed distance, as the env counts one), by the env's
own kinematics and collision distances. The configuration that defined the target (a random pose free of self
collisions) is tried first; where an obstacle touches it, damped least-squares inverse kinematics from random
joint configurations searches for another, stepping (approximately) in the null space of the end effector's
Jacobian away from the nearest collision. The search can miss a pose, so the share it finds is a lower estimate of
the feasible share; the feasible share itself bounds any agent's reached rate from above, since whether a
collision-free path leads there from the start pose is not checked. A found share well above an aim shows that the
aim is not beyond the task's goals. Static obstacles only: with moving ones the answer depends on when the target
is reached.
"""

from __future__ import annotations

import argparse
import dataclasses
import json

import jax
import jax.numpy as jnp
import numpy as np

import envs
from agents import provenance
from envs import validation
from tools import literal_or_text, run_cli


@dataclasses.dataclass(frozen=True)
class SearchConfig:
    """The inverse-kinematics search for the episodes whose target configuration collides."""

    restarts: int = 32
    """Random joint configurations each search starts from (uniform within the joint ranges)."""
    iterations: int = 200
    """Damped least-squares steps from each start."""
    damping: float = 0.05
    """Damping of the least-squares step (m): larger is slower and steadier near singular poses."""
    clearance_step: float = 0.5
    """Null-space step along the gradient of the nearest collision distance (rad per m), taken while that
    distance is below `margin`."""
    margin: float = 0.02
    """Distance (m) under which the null-space step pushes away from the nearest collision."""

    def __post_init__(self):
        for name in ("restarts", "iterations"):
            validation.integer(name, getattr(self, name), 1)
        for name in ("damping", "clearance_step", "margin"):
            validation.positive(name, getattr(self, name))


def arm_env(name: str, options: dict | None = None):
    """The registered arm env `name` with config `options`; ValueError for an env without an arm or with moving
    obstacles."""
    env = envs.make(name, **(options or {}))
    if not hasattr(env, "robot"):
        raise ValueError(f"env={name!r} is invalid: it has no arm; allowed are the arm envs "
                         "(ur5e-reach, ur5e-reach-avoid, panda-reach, panda-reach-avoid).")
    motion = getattr(env.config, "obstacle_motion", "static")
    if motion != "static":
        raise ValueError(f"obstacle_motion={motion!r} is invalid here: allowed is 'static' (a moving obstacle's "
                         "feasible configurations depend on when the target is reached).")
    return env


def pose_check(env, info, qpos):
    """(distance of the end effector from the target, smallest collision distance: self or obstacle) at `qpos`."""
    kin = env.robot.kinematics(qpos)
    return (jnp.linalg.norm(kin.ee_pos - info["target_pos"]),
            jnp.min(env.collision_distances(kin.geom_xpos, kin.geom_xmat, info)))


def in_target_and_clear(env, distance, clearance):
    """Whether a pose at these (target distance, collision distance) counts: in the target, no collision (the env
    counts a negative distance as one)."""
    return (distance < env.config.target_radius) & (clearance >= 0)


def solve(env, info, qpos, search: SearchConfig):
    """`qpos` moved by damped least-squares inverse kinematics towards the target, pushed in the null space of the
    end effector's Jacobian away from the nearest collision while it is closer than `search.margin`."""
    robot = env.robot
    low, high = jnp.asarray(robot.joint_low), jnp.asarray(robot.joint_high)
    ee = lambda q: robot.kinematics(q).ee_pos  # noqa: E731
    nearest = lambda q: pose_check(env, info, q)[1]  # noqa: E731
    eye3, eye = jnp.eye(3), jnp.eye(robot.nq)

    def step(q, _):
        jac, position = jax.jacfwd(lambda x: (ee(x),) * 2, has_aux=True)(q)  # one pass for both
        pinv = jac.T @ jnp.linalg.inv(jac @ jac.T + search.damping ** 2 * eye3)
        task = pinv @ (info["target_pos"] - position)
        clearance, grad = jax.value_and_grad(nearest)(q)
        away = jnp.where(clearance < search.margin, search.clearance_step, 0.0) * (eye - pinv @ jac) @ grad
        return jnp.clip(q + task + away, low, high), None

    return jax.lax.scan(step, qpos, None, length=search.iterations)[0]


def search_episode(env, info, key, search: SearchConfig):
    """Whether any restart of `solve` ends in the target free of collisions."""
    robot = env.robot
    starts = jax.random.uniform(key, (search.restarts, robot.nq), minval=jnp.asarray(robot.joint_low),
                                maxval=jnp.asarray(robot.joint_high))
    ends = jax.vmap(lambda q: solve(env, info, q, search))(starts)
    distance, clearance = jax.vmap(lambda q: pose_check(env, info, q))(ends)
    return jnp.any(in_target_and_clear(env, distance, clearance))


def reset_infos(env, episodes: int, seed: int) -> dict:
    """The `info` of `episodes` resets of `env` under keys split from `seed`, stacked."""
    keys = jax.random.split(jax.random.PRNGKey(seed), episodes)
    return jax.jit(jax.vmap(lambda k: env.reset(k).info))(keys)


def feasibility(env, infos: dict, seed: int, search: SearchConfig = SearchConfig()) -> dict:
    """For each episode of the stacked `infos`: whether its target configuration is free of collisions
    (`target_pose_clear`, a share) and whether it or a configuration the search finds (from keys split from
    `seed`) is (`feasible`, a share; `infeasible_episodes`, the indices of the others)."""
    episodes = len(infos["target_pos"])
    distance, clearance = jax.jit(jax.vmap(lambda info: pose_check(env, info, info["target_qpos"])))(infos)
    clear = np.asarray(in_target_and_clear(env, distance, clearance))
    blocked = np.flatnonzero(~clear)
    found = np.zeros(episodes, bool)
    if blocked.size:
        picked = jax.tree.map(lambda x: x[blocked], infos)
        search_keys = jax.random.split(jax.random.PRNGKey(seed), episodes)[blocked]
        search_each = jax.jit(jax.vmap(lambda i, k: search_episode(env, i, k, search)))
        found[blocked] = np.asarray(search_each(picked, search_keys))
    feasible = clear | found
    return {"episodes": episodes, "target_pose_clear": float(clear.mean()), "found_by_search": int(found.sum()),
            "feasible": float(feasible.mean()), "infeasible_episodes": np.flatnonzero(~feasible).tolist(),
            "target_pose_clearance": np.asarray(clearance).tolist()}


def main(argv: list[str] | None = None) -> dict:
    p = argparse.ArgumentParser(prog="python -m tools.feasibility", description=__doc__.splitlines()[0])
    p.add_argument("env", help="registered arm env (static obstacles)")
    p.add_argument("--option", action="append", default=[], metavar="FIELD=VALUE",
                   help="an env config field, repeatable (e.g. obstacle_radius=0.15, workspace=front)")
    p.add_argument("--episodes", type=int, default=4096)
    p.add_argument("--seed", type=int, default=7, help="seed of the episodes' resets (default 7); the search's starts take seed + 1")
    p.add_argument("--restarts", type=int, default=SearchConfig.restarts)
    p.add_argument("--iterations", type=int, default=SearchConfig.iterations)
    p.add_argument("--json", metavar="PATH", help="write the summary with its provenance")
    args = p.parse_args(argv)
    if args.episodes < 1:
        raise ValueError(f"--episodes {args.episodes} is invalid: allowed is an integer >= 1.")
    options = {}
    for item in args.option:
        field, sep, value = item.partition("=")
        if not sep:
            raise ValueError(f"--option {item!r} is invalid: allowed is FIELD=VALUE.")
        options[field] = literal_or_text(value)
    search = SearchConfig(restarts=args.restarts, iterations=args.iterations)
    env = arm_env(args.env, options)
    made = provenance.stamp(provenance.command(None if argv is None else [__file__] + list(argv)))
    result = feasibility(env, reset_infos(env, args.episodes, args.seed), args.seed + 1, search)
    print(f"{args.env}{' ' + str(options) if options else ''}: {result['feasible']:.2%} of {args.episodes} episodes feasible "
          f"(target configuration clear in {result['target_pose_clear']:.2%}, {result['found_by_search']} more "
          f"found by the search; {len(result['infeasible_episodes'])} infeasible)")
    if args.json:
        with open(args.json, "w") as f:
            json.dump({**made, "env": args.env, "options": options, "seed": args.seed,
                       "search": dataclasses.asdict(search), **result}, f, indent=1)
    return result


if __name__ == "__main__":
    run_cli(main)
