"""Where moving obstacles go in an episode: how often one runs into the geoms no joint moves (a collision no policy
can avoid) and how often one hits an arm that stands still.

    python -m benchmarks.obstacle_paths ur5e-reach-avoid-ppo-moving3 panda-reach-avoid-ppo-moving3 --num-envs 4096 \
        --out results/obstacles/obstacle_paths

Per preset (its env config): the episodes' starts are drawn as the env draws them (the env's own `reset`), then
every obstacle follows its motion for the whole episode, read at the start of every control step and after the
last. An obstacle that reaches the base or the first link (`robot.fixed_geoms`: no joint moves them, the first
link only spins about its own axis) collides whatever the policy does, so their share of episodes is a floor of
`obstacle_collision` for every policy; the other figure is an arm held in its start pose (every robot geom). Read
at control steps, not physics substeps, both slightly undercount a pass of under one control step.

Writes `--out`.json (per preset, with command, code version, device and date) and `--out`.md (the table).
"""

from __future__ import annotations

import argparse
import json

import jax
import jax.numpy as jnp
import numpy as np

import envs
from agents import presets, provenance
from tools import run_cli


def first_contacts(env, info, geom_xpos, geom_xmat, geoms) -> jax.Array:
    """One episode (unbatched): the first control step at whose start an obstacle touches one of `geoms` of the
    robot posed as `geom_xpos` / `geom_xmat`, or -1 if none does within the episode."""
    cfg = env.config
    steps = jnp.arange(cfg.episode_length + 1)

    def closest(step):
        at_step = env.task_at(info, step * cfg.substeps)
        return jnp.min(env.per_obstacle(at_step, lambda c, r: env.robot.obstacle_distances(geom_xpos, geom_xmat, c, r,
                                                                                            geoms)))

    touching = jax.vmap(closest)(steps) < 0
    return jnp.where(jnp.any(touching), jnp.argmax(touching), -1)


def measure(env, num_envs: int, seed: int = 0) -> dict:
    """`num_envs` episode starts of `env` (moving obstacles): per episode the first contact with the fixed geoms and
    with a standing arm's geoms; the shares of episodes with one, the quartiles of the fixed geoms' step, and the
    share of starts the sampler did not find among its candidates (`reset_fallback`)."""
    if not env.motion.moves:
        raise ValueError(f"obstacle_motion={env.config.obstacle_motion!r} is invalid here: allowed is a moving one "
                         "(a static obstacle starts clear of the arm and stays there).")
    robot = env.robot
    states = jax.jit(jax.vmap(env.reset))(jax.random.split(jax.random.PRNGKey(seed), num_envs))
    data = states.pipeline_state

    @jax.jit
    @jax.vmap
    def contacts(info, geom_xpos, geom_xmat):
        return (first_contacts(env, info, geom_xpos, geom_xmat, robot.fixed_geoms),
                first_contacts(env, info, geom_xpos, geom_xmat, robot.robot_geoms))

    fixed, standing = map(np.asarray, contacts(states.info, data.geom_xpos, data.geom_xmat))
    hit = fixed >= 0
    return {"episodes": num_envs, "fixed_geoms": [robot.mj_model.geom(int(g)).name for g in robot.fixed_geoms],
            "fixed_share": float(hit.mean()), "standing_share": float((standing >= 0).mean()),
            "fallback_share": float(np.mean(states.metrics["reset_fallback"])),
            "fixed_step_quartiles": np.percentile(fixed[hit], [25, 50, 75]).tolist() if hit.any() else None,
            "episode_length": env.config.episode_length}


def markdown(meta: dict, rows: dict) -> str:
    lines = [f"# Moving obstacles' paths ({meta['device']}, {meta['date']})", "",
             f"Command: `{meta['command']}`, code {meta['code']}; {meta['num_envs']:,} episode starts per preset "
             f"(reset key {meta['seed']}).", "",
             "| preset | env | geoms no joint moves | an obstacle runs into them | first at control step (quartiles) "
             "| an arm standing still is hit | starts not found among the candidates |", "|---|---|---|---:|---|---:|---:|"]
    for name, r in rows.items():
        q = ("none" if r["fixed_step_quartiles"] is None
             else " / ".join(f"{v:.0f}" for v in r["fixed_step_quartiles"]) + f" of {r['episode_length']}")
        lines.append(f"| {name} | {r['env_name']} | {', '.join(r['fixed_geoms'])} | {100 * r['fixed_share']:.1f} % | "
                     f"{q} | {100 * r['standing_share']:.1f} % | {100 * r['fallback_share']:.2f} % |")
    return "\n".join(lines) + "\n"


def main(argv=None) -> None:
    """Parses the command line, measures each preset, prints the table and writes --out's files."""
    parser = argparse.ArgumentParser(prog="python -m benchmarks.obstacle_paths", description=__doc__.split("\n\n")[0])
    parser.add_argument("presets", nargs="+", help="presets whose env has moving obstacles")
    parser.add_argument("--num-envs", type=int, default=4096, help="episode starts per preset")
    parser.add_argument("--seed", type=int, default=0, help="the reset key's seed")
    parser.add_argument("--out", help="write OUT.json and OUT.md")
    args = parser.parse_args(argv)
    if args.num_envs < 1:
        parser.error(f"--num-envs={args.num_envs} is invalid: allowed is an integer >= 1")
    rows = {}
    for name in args.presets:
        config = presets.make_config(name)
        env = envs.registry.from_config(config.env_name, config.env)
        rows[name] = {"env_name": config.env_name, **measure(env, args.num_envs, args.seed)}
    meta = {**provenance.stamp(), "num_envs": args.num_envs, "seed": args.seed}
    text = markdown(meta, rows)
    print(text)
    if args.out:
        with open(args.out + ".json", "w") as f:
            json.dump({**meta, "presets": rows}, f, indent=1)
        with open(args.out + ".md", "w") as f:
            f.write(text)


if __name__ == "__main__":
    run_cli(main)
