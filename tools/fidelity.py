"""The UR5e's learner-free numbers against the paper's: the baseline table, joint speeds, joint-limit margins.

    python -m tools.fidelity --episodes 1024 --out results/fidelity/default.json
    python -m tools.fidelity --env-option init_range=limited --variant no_base damping=1.5 --out x.json

The paper pins: Table "reaching baselines" (section "Baselines"), "Initial pose and target sampling", "Simulation
settings" (Menagerie's UR5e, end-effector cylinder made a capsule, damping added as the default controller ran up
to 5x the real speeds) and "Reach Task" (125 steps of 20 x 2 ms, a collision ends the episode). Findings:
results/fidelity/README.md. Baselines are `agents.baselines`' agents, one rollout per (action mode, agent) read
at both target radii (reach-and-stay: the radius does not change the motion); rates come with their binomial
standard error sqrt(p (1 - p) / n), and one --seed draws the same episodes for every configuration (but resets
whose rejection sampling a variant changes), so differences between configurations are paired.
VARIANTS are EXPERIMENTAL hypotheses without an env field: each edits one built env in place, never the env's
defaults.
"""

from __future__ import annotations

import argparse
import json
import os
import sys
import time

import jax
import jax.numpy as jnp
import mujoco
import numpy as np

import envs
from agents import baselines, provenance
from envs import collision

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
RADII = (0.01, 0.02)
ACTIONS = ("absolute", "relative")
AGENTS = ("random", "standstill", "pseudo_ik")
LIMIT_MARGINS = (0.1, 0.5)  # distances (rad) from a joint limit counted as "near the limit"
SPEED_STEPS = 25  # env steps (1 s) of the speed scenarios


def _no_base(env, value):
    """Menagerie's UR5e has no base collision geom: drop our base sphere's pairs."""
    robot, base = env.robot, env.robot.mj_model.geom("base").id
    robot.self_pairs = robot.self_pairs[np.all(robot.self_pairs != base, axis=1)]


def _floor(env, value):
    """A floor at z = 0 (Menagerie's scene.xml) counted as a self collision (but for base and shoulder)."""
    robot, own = env.robot, env.robot.self_distances
    geoms = np.array([g for g in robot.robot_geoms if robot.mj_model.geom(g).name not in ("base", "shoulder")])

    def with_floor(xpos, xmat):
        start, end = collision.capsule_segments(xpos, xmat, robot.geom_half)
        floor = jnp.minimum(start[..., geoms, 2], end[..., geoms, 2]) - robot.geom_radius[geoms]
        return jnp.concatenate([own(xpos, xmat), floor], axis=-1)

    robot.self_distances = with_floor


def _step_end(env, value):
    """Collisions checked at env-step boundaries only (Brax's pipeline_step returns the last substep's data)."""
    run = env.physics.run
    env.physics.run = lambda data, distances: run(data, lambda *a: jnp.full(2, jnp.inf))


def _contacts(env, value):
    """Contact forces on the model's pairs (the paper's MJX model kept contacts on; combine with step_end)."""
    env.robot.mj_model.opt.disableflags &= ~int(mujoco.mjtDisableBit.mjDSBL_CONTACT)


def _target_limited(env, value):
    """Target poses from the limited (360 deg) range, like `init_range="limited"` start poses."""
    robot, (low, high) = env.robot, env.robot.joint_range("limited")
    as_targets = lambda qpos, kin, free: (kin.ee_pos, qpos, free)
    robot.sample_reachable = lambda key, num: as_targets(*robot.sample_poses(key, num, low, high))


def _elbow_2pi(env, value):
    """The elbow's range +-2 pi (UR's own limit; Menagerie's is +-pi): sampling, action mapping and clipping."""
    m, robot = env.robot.mj_model, env.robot
    m.jnt_range[2], m.actuator_ctrlrange[2] = (-2 * np.pi, 2 * np.pi), (-2 * np.pi, 2 * np.pi)
    robot.joint_low[2], robot.joint_high[2] = -2 * np.pi, 2 * np.pi  # the arrays the env's ranges share


def _ctrl_pi(env, value):
    """Absolute actions and servo targets span +-pi (targets come from +-pi poses); start poses keep the full range."""
    robot = env.robot
    env._init_low, env._init_high = robot.joint_low.copy(), robot.joint_high.copy()
    for limits in (robot.joint_low, robot.joint_high):  # in place: the arrays the env's action mapping reads
        np.clip(limits, -np.pi, np.pi, out=limits)


def _ee_at_wrist_3(env, value):
    """The end effector at wrist_3's frame origin (on the wrist axis) instead of the tool flange 0.1 m out."""
    env.robot.mj_model.site_pos[env.robot.ee_site] = 0.0  # before the first kinematics call caches the model


def _wrist_3(env, value):
    """wrist_3's collision capsule resized, "HALF[,RADIUS]" in m: Menagerie's end-effector cylinder (r 0.04, half-height
    0.02) spans 0.06-0.10 m along the flange axis; our capsule of the same size numbers reaches 0.02-0.14 m."""
    robot, g = env.robot, env.robot.mj_model.geom("wrist_3").id
    half, *radius = (float(x) for x in value.split(","))
    robot.geom_half[g] = half  # in place, before the first distance call is traced
    if radius:
        robot.geom_radius[g] = radius[0]


def _damping(env, value):
    """Joint damping x v, or x v_i per joint for a comma-separated list (0: Menagerie's, no damping)."""
    env.robot.mj_model.dof_damping *= np.array(value.split(","), float)


def _position_servos(env, value):
    """Older Menagerie revisions' UR5e servos (the reference model's comment): <position> kp 3500 (shoulder, elbow)
    and 3000 (wrists) without a velocity gain, joint damping 200 and 15 in place of ours; forces limited as before."""
    m = env.robot.mj_model
    kp, damping = np.array([3500.0] * 3 + [3000.0] * 3), np.array([200.0] * 3 + [15.0] * 3)
    m.actuator_gainprm[:, 0], m.actuator_biasprm[:, 1], m.actuator_biasprm[:, 2] = kp, -kp, 0.0
    m.dof_damping[:] = damping


VARIANTS = {  # name -> apply(env, value string); on the command line NAME or NAME=VALUE
    "damping": _damping, "position_servos": _position_servos,
    "no_base": _no_base, "floor": _floor, "step_end": _step_end, "contacts": _contacts, "ee_wrist_3": _ee_at_wrist_3,
    "target_limited": _target_limited, "elbow_2pi": _elbow_2pi, "ctrl_pi": _ctrl_pi,
    "wrist_3": _wrist_3}


def build(options: dict, variants: list[str]):
    """The unwrapped reach env of `options` with the `variants` applied, in order."""
    return apply_variants(envs.make("ur5e-reach", **options), variants)


def apply_variants(env, variants: list[str]):
    """`env` with the `variants` ("NAME[=VALUE]") applied in place, in order; ValueError naming an unknown or
    malformed one."""
    for item in variants:
        name, _, value = item.partition("=")
        if name not in VARIANTS:
            raise ValueError(f"--variant {item!r} is unknown: allowed are {', '.join(VARIANTS)}.")
        try:
            VARIANTS[name](env, value)
        except ValueError as error:  # a malformed value (damping=x, damping=1,2): numpy's message names neither
            raise ValueError(f"--variant {item!r} is invalid: {str(error).strip()}.") from error
    env.robot.put_on_device()  # MJX steps the MuJoCo model as the variants left it
    return env


def pseudo_ik_targets(env, start_q, target_q, mode: str):
    """The configuration the pseudo-IK agent commands: the target pose's angles ("sampled") or ("nearest") for each
    joint the one of angle, angle +- 2 pi within its range nearest the start pose (the same pose, a shorter path)."""
    if mode == "sampled":
        return target_q
    low, high = env.robot.joint_low[:, None] - 1e-6, env.robot.joint_high[:, None] + 1e-6
    options = target_q[..., None] + jnp.array([0.0, -2 * np.pi, 2 * np.pi])
    dist = jnp.where((options >= low) & (options <= high), jnp.abs(options - start_q[..., None]), jnp.inf)
    return jnp.take_along_axis(options, jnp.argmin(dist, -1)[..., None], -1)[..., 0]


def rollout(env, agent: str, key, num: int, pseudo_ik: str = "sampled"):
    """(reset state, pseudo-IK goal, records (distance, self_collision, done, qpos) `[steps, num, ...]`)."""
    benv = envs.wrap(env, autoreset=False)
    base_act, index = baselines.make_act(benv), baselines.index(agent)

    @jax.jit
    def run(key):
        start = benv.reset(jax.random.split(key, num))
        goal = pseudo_ik_targets(env, start.pipeline_state.qpos, start.info["target_qpos"], pseudo_ik)

        def step(s, k):
            ik = baselines.joint_target_action(env.config, env.robot, goal, s.pipeline_state.qpos)
            n = benv.step(s, ik if agent == "pseudo_ik" else base_act(index, s, start, k))
            return n, (n.metrics["distance"], n.metrics["self_collision"], n.done, n.pipeline_state.qpos)

        keys = jax.random.split(jax.random.fold_in(key, 1), env.config.episode_length)
        return start, goal, jax.lax.scan(step, start, keys)[1]

    return jax.device_get(run(key))


def rate(values) -> dict:
    p = float(np.mean(values))  # a share of episodes and its binomial standard error
    return {"rate": p, "se": float(np.sqrt(p * (1 - p) / len(values)))}


def episode_summary(env, records, goal) -> dict:
    """Outcomes of one rollout: collided, reached at each radius, final distances, and the share of all episodes
    that end without a collision with a joint within 0.05 rad of a limit or more than 0.1 rad from `goal`."""
    dist, coll, done, qpos = (np.asarray(r) for r in records)
    steps, n = dist.shape
    end = np.where(done.any(0), np.argmax(done > 0, axis=0), steps - 1)
    alive, collided, q_end = np.arange(steps)[:, None] <= end, coll[end, np.arange(n)] > 0, qpos[end, np.arange(n)]
    out = {"self_collision": rate(collided), "collision_pairs": collision_pairs(env.robot, q_end[collided]),
           "collision_step_mean": float(np.mean(end[collided] + 1)) if collided.any() else None}
    for r in RADII:
        out[f"reached_{r:g}"] = rate(np.any((dist < r) & alive, axis=0) & ~collided)
    final = dist[end, np.arange(n)]  # last10: the last 10 steps' mean, 0 for a collided episode
    last10 = np.array([dist[max(0, e - 9):e + 1, i].mean() for i, e in enumerate(end)]) * ~collided
    for name, d in (("distance", final), ("distance_last10_collided0", last10)):
        out[name] = {"mean": float(d.mean()), "std": float(d.std())}
    gap = np.minimum(q_end - env.robot.joint_low, env.robot.joint_high - q_end).min(-1)
    out["pinned_at_end"] = rate((gap < 0.05) & ~collided)
    out["far_from_goal_at_end"] = rate((np.abs(q_end - np.asarray(goal)).max(-1) > 0.1) & ~collided)
    return out


def collision_pairs(robot, qpos) -> dict:
    """Share of collided episodes whose final pose has each self-collision pair (geom names) the deepest."""
    kin = robot.kinematics(jnp.asarray(qpos).reshape(-1, robot.nq))
    dist = np.asarray(robot.self_distances(kin.geom_xpos, kin.geom_xmat))
    names = [" - ".join(robot.mj_model.geom(g).name for g in pair) for pair in robot.self_pairs]
    names = np.array(names + ["floor"] * (dist.shape[-1] - len(names)))  # the floor variant's extra distances
    found, counts = np.unique(names[np.argmin(dist, -1)], return_counts=True)
    return {str(found[i]): counts[i] / len(qpos) for i in np.argsort(-counts)}


def baseline_table(options, variants, num, seed, agents, actions, pseudo_ik):
    """(rows: every (action mode, agent) beside the paper's numbers (UR5e), the last reset state)."""
    with open(os.path.join(ROOT, "assets", "paper_numbers.json")) as f:  # the paper's Table "reaching baselines"
        table = json.load(f)["baselines"]
    paper, rows = {(r[0], r[1]): dict(zip(table["columns"][2:], r[2:])) for r in table["rows"]}, []
    for action in actions:
        env = build({**options, "action": action}, variants)
        for agent in agents:
            t0 = time.perf_counter()
            start, goal, records = rollout(env, agent, jax.random.PRNGKey(seed), num, pseudo_ik)
            rows.append(row := {"action": action, "agent": agent, **episode_summary(env, records, goal),
                                "paper": {f"{r:g}": paper.get((agent, r)) for r in RADII},
                                "seconds": round(time.perf_counter() - t0, 1)})
            shown = [f"reached_{r:g}" for r in RADII] + ["self_collision"]
            print(f"{action:8s} {agent:10s}", *(f"{k} {100 * row[k]['rate']:5.1f} ± {100 * row[k]['se']:.1f}"
                                                for k in shown), f"distance {row['distance']['mean']:.3f}", flush=True)
    return rows, start


def speed_profile(options, variants, num, seed) -> dict:
    """|joint speed| over SPEED_STEPS steps from reset poses, every joint commanded to the far end of its range
    (`full_command`, absolute) or a full relative step towards its middle (`relative_steps`): peak (rad/s, / limit),
    share of steps ending above the limit, mean speed of the last half, (relative) share of the step covered."""
    out = {}
    for scenario, action in (("full_command", "absolute"), ("relative_steps", "relative")):
        env = build({**options, "action": action}, variants)
        benv, mid = envs.wrap(env, autoreset=False), (env.robot.joint_low + env.robot.joint_high) / 2

        @jax.jit
        def run(key):
            start = benv.reset(jax.random.split(key, num))
            direction = jnp.where(start.pipeline_state.qpos > mid, -1.0, 1.0)
            step = lambda s, _: (lambda n: (n, (n.pipeline_state.qvel, n.pipeline_state.qpos)))(benv.step(s, direction))
            return start.pipeline_state.qpos, jax.lax.scan(step, start, None, length=SPEED_STEPS)[1]

        q0, (qvel, qpos) = jax.device_get(run(jax.random.PRNGKey(seed)))
        limit, peak = env.robot.velocity_limits, np.abs(qvel).max(axis=(0, 1))
        moves = np.abs(np.diff(np.concatenate([q0[None], qpos]), axis=0))
        speed = (moves / env.dt)[SPEED_STEPS // 2:].mean(axis=(0, 1))
        out[scenario] = {"peak": peak.tolist(), "peak_over_limit": (peak / limit).tolist(), "mean_speed_last_half":
                         speed.tolist(), "share_steps_over_limit": (np.abs(qvel) > limit).mean(axis=(0, 1)).tolist()}
        if action == "relative":
            step = env.config.relative_step(env.robot.joint_low, env.robot.joint_high)
            out[scenario]["gap_closed_per_step"] = (speed * env.dt / step).tolist()
    return out


def reset_distances(env, seed: int, num: int = 16384) -> dict:
    """Start-to-target distance over `num` resets (the standstill row's distance but the sag), without physics."""
    keys = jax.random.split(jax.random.PRNGKey(seed + 1), num)
    d = np.asarray(jax.jit(jax.vmap(env.reset))(keys).metrics["distance"])
    return {"num": num, "mean": float(d.mean()), "std": float(d.std()), "se_mean": float(d.std() / np.sqrt(num))}


def limit_margins(env, start) -> dict:
    """Share of start poses and of target poses with a joint within each LIMIT_MARGINS of its range's ends."""
    gaps = {name: np.minimum(np.asarray(q) - env.robot.joint_low, env.robot.joint_high - np.asarray(q))
            for name, q in (("start", start.pipeline_state.qpos), ("target", start.info["target_qpos"]))}
    return {name: {f"{m:g}": {"any_joint": float(np.mean(g.min(-1) < m)), "per_joint": np.mean(g < m, 0).tolist()}
                   for m in LIMIT_MARGINS} for name, g in gaps.items()}


def parse(argv):
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("--episodes", type=int, default=1024, help="episodes per (mode, agent)")
    p.add_argument("--seed", type=int, default=0, help="reset seed: the same episodes for every configuration")
    p.add_argument("--env-option", nargs="+", default=[], metavar="FIELD=VALUE", help="env config fields (JSON values)")
    p.add_argument("--variant", nargs="+", default=[], metavar="NAME[=VALUE]", help=", ".join(VARIANTS))
    p.add_argument("--agents", nargs="+", choices=AGENTS, default=list(AGENTS))
    p.add_argument("--actions", nargs="+", choices=ACTIONS, default=list(ACTIONS))
    p.add_argument("--pseudo-ik", choices=("sampled", "nearest"), default="sampled",
                   help="experimental: the pseudo-IK agent's joint angles (see pseudo_ik_targets)")
    p.add_argument("--no-speed", action="store_true", help="skip the speed profile")
    p.add_argument("--out", required=True, help="JSON file to write")
    args = p.parse_args(argv)
    if args.episodes < 1 or any("=" not in item for item in args.env_option):
        raise ValueError(f"--episodes={args.episodes} --env-option {args.env_option} is invalid: allowed are an "
                         "integer >= 1 and FIELD=VALUE items.")
    args.options = {k: _json_or_text(v) for k, v in (item.split("=", 1) for item in args.env_option)}
    if "action" in args.options:  # baseline_table would override it, unnoticed but for the JSON's env_options
        raise ValueError(f"--env-option action={args.options['action']!r} is invalid: allowed is --actions "
                         f"({', '.join(ACTIONS)}), which sets the action mode of each rollout.")
    return args


def _json_or_text(value: str):
    try:
        return json.loads(value)
    except json.JSONDecodeError:
        return value


def main(argv=None):
    args = parse(sys.argv[1:] if argv is None else argv)
    t0 = time.perf_counter()
    rows, start = baseline_table(args.options, args.variant, args.episodes, args.seed, args.agents,
                                 args.actions, args.pseudo_ik)
    env = build({**args.options, "action": args.actions[-1]}, args.variant)
    result = {**provenance.stamp(), "env_options": args.options, "variants": args.variant,
              "pseudo_ik": args.pseudo_ik, "episodes": args.episodes, "seed": args.seed, "baselines": rows,
              "limit_margins": limit_margins(env, start), "reset_distances": reset_distances(env, args.seed)}
    print("start-to-target distance over resets: {mean:.4f} ± {std:.4f} m".format(**result["reset_distances"]))
    if not args.no_speed:
        result["speed"] = speed_profile(args.options, args.variant, min(args.episodes, 256), args.seed)
        for name, s in result["speed"].items():
            print(name, "peak / limit", np.round(s["peak_over_limit"], 2),
                  "mean speed", np.round(s["mean_speed_last_half"], 2))
    result["seconds"] = round(time.perf_counter() - t0, 1)
    os.makedirs(os.path.dirname(os.path.abspath(args.out)), exist_ok=True)
    with open(args.out, "w") as f:
        json.dump(result, f, indent=1)
    print(f"wrote {args.out} ({result['seconds']} s)")


if __name__ == "__main__":
    main()
