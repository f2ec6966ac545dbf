"""What the paper's link distance (eq. 3's d_i from each link frame's origin) reads when a link touches an obstacle.

    python -m tools.link_distance_probe --env ur5e-reach-avoid --num-poses 200000 --json out.json

Learner-free and kinematic: `num_poses` joint configurations drawn uniformly from the joint range, each with one
obstacle of radius 0.05-0.1 m (the moving-obstacle task's range) centred at the centre of a random geom of the links
the distance covers (`robot.obstacle_geoms`) moved by a Gaussian offset of `offset` m per axis, so that contacts are
common: the shares describe these random poses and placements, not a trained agent's episodes. For each link it
counts the poses where the link's capsules touch the obstacle (`link_distance="surface"` < 0) and summarises what
the `"origin"` distance of that link (the observation `link_obstacle_dist` and eq. (3)'s penalty read it) says
then: its median, its 90th percentile and the share of contacts it puts over 10 cm away. `nearest` does the same
for the smallest origin distance over all links, which is what a policy could at best read off the observation. A
contact along a long link sits far from the link's origin, so its origin distance says the obstacle is far.
"""

from __future__ import annotations

import argparse
import json

import jax
import jax.numpy as jnp
import mujoco
import numpy as np

import envs
from agents import provenance
from tools import run_cli

FAR = 0.1
"""An origin distance above this (m) at contact counts as a contact the origin distance hides."""


def summarize(origin: np.ndarray, surface: np.ndarray, names: list[str]) -> dict:
    """Per link (columns of the `[poses, links]` distances, named `names`) and for the nearest link: contacts, the
    median and 90th percentile of the origin distance at contact, and the share of contacts it puts beyond `FAR`."""

    def stats(values: np.ndarray) -> dict:
        if values.size == 0:
            return {"contacts": 0}
        return {"contacts": int(values.size), "origin_median": float(np.median(values)),
                "origin_p90": float(np.percentile(values, 90)), "share_far": float(np.mean(values > FAR))}

    touching = surface < 0.0
    per_link = {name: stats(origin[touching[:, i], i]) for i, name in enumerate(names)}
    return {"links": per_link, "nearest": stats(np.min(origin[np.any(touching, axis=1)], axis=1))}


def probe(env_name: str, num_poses: int, offset: float, seed: int) -> dict:
    """`summarize` over `num_poses` random poses of `env_name`'s robot, one obstacle near each."""
    robot = envs.make(env_name).unwrapped.robot  # its kinematics and capsules only: nothing is simulated
    k_pose, k_radius, k_geom, k_offset = jax.random.split(jax.random.PRNGKey(seed), 4)
    qpos = jax.random.uniform(k_pose, (num_poses, len(robot.joint_low)), minval=robot.joint_low,
                              maxval=robot.joint_high)
    kin = robot.kinematics(qpos)  # batched over the poses
    radius = jax.random.uniform(k_radius, (num_poses,), minval=0.05, maxval=0.1)
    geom = jnp.asarray(robot.obstacle_geoms)[jax.random.randint(k_geom, (num_poses,), 0, len(robot.obstacle_geoms))]
    center = kin.geom_xpos[jnp.arange(num_poses), geom] + offset * jax.random.normal(k_offset, (num_poses, 3))

    def distances(mode):
        return np.asarray(jax.vmap(lambda xpos, gpos, gmat, c, r: robot.link_obstacle_distances(
            xpos, gpos, gmat, c, r, mode))(kin.xpos, kin.geom_xpos, kin.geom_xmat, center, radius))

    names = [mujoco.mj_id2name(robot.mj_model, mujoco.mjtObj.mjOBJ_BODY, int(b)) for b in robot.link_bodies]
    return summarize(distances("origin"), distances("surface"), names)


def markdown(summary: dict) -> str:
    """The summary as a table: one row per link and one for the nearest link."""
    rows = ["| link | contacts | origin distance at contact: median | 90th percentile | share over 10 cm |",
            "|---|---:|---:|---:|---:|"]
    for name, s in [*summary["links"].items(), ("nearest link", summary["nearest"])]:
        if s["contacts"]:
            rows.append(f"| {name} | {s['contacts']} | {100 * s['origin_median']:.1f} cm | "
                        f"{100 * s['origin_p90']:.1f} cm | {100 * s['share_far']:.0f} % |")
        else:
            rows.append(f"| {name} | 0 | - | - | - |")
    return "\n".join(rows)


def main(argv: list[str] | None = None) -> dict:
    """Parses the options (refusing impossible ones, naming them), probes, prints the table, writes --json."""
    p = argparse.ArgumentParser(prog="python -m tools.link_distance_probe", description=__doc__.splitlines()[0])
    p.add_argument("--env", default="ur5e-reach-avoid", help="an arm env (its robot's links are probed)")
    p.add_argument("--num-poses", type=int, default=200_000)
    p.add_argument("--offset", type=float, default=0.12, help="std (m) of the obstacle's offset from a geom centre")
    p.add_argument("--seed", type=int, default=0)
    p.add_argument("--json", metavar="PATH", help="write the summary with what made it")
    args = p.parse_args(argv)
    if args.num_poses < 1:
        raise ValueError(f"--num-poses {args.num_poses} is invalid: allowed is an integer >= 1.")
    if not args.offset > 0:
        raise ValueError(f"--offset {args.offset} is invalid: allowed is a number > 0 (m).")
    if envs.registry.spec(args.env).robot is None:  # an unknown name: ValueError listing the names
        arms = [name for name in envs.registry.names() if envs.registry.spec(name).robot is not None]
        raise ValueError(f"--env {args.env!r} is invalid: it has no robot to probe; allowed are {', '.join(arms)}.")
    made = provenance.stamp(provenance.command(None if argv is None else [__file__] + list(argv)))
    summary = probe(args.env, args.num_poses, args.offset, args.seed)
    print(markdown(summary))
    if args.json:
        with open(args.json, "w") as f:
            json.dump({**made, "env": args.env, "num_poses": args.num_poses, "offset": args.offset,
                       "seed": args.seed, "summary": summary}, f, indent=1)
    return summary


if __name__ == "__main__":
    run_cli(main)
