"""How fast relative control can move an arm, and how much of that speed a policy uses on its way to the target.

    python -m tools.approach_speed --checkpoint results/checkpoints/ur5e-reach-ppo --num-envs 256 --json out.json
    python -m tools.approach_speed --env ur5e-reach --action-scale 0.6            # the cap only

Relative control (paper, "Action Space") sets each joint's servo target to the current position plus
`action * action_scale`. A servo with stiffness kp and damping d (servo kv + joint damping) closes a
gap with time constant d / kp, so within one env step only part of the commanded step is covered, and
the next step re-bases the target on where the joint got to. `servo_cap` measures that per joint with
the env's own physics: every joint commanded a full step (|action| = 1, towards the middle of its
range) for `CAP_STEPS` steps from reset poses; the last steps' mean displacement is the most a joint
can move per env step. `policy_approach` rolls out a checkpoint's deterministic policy (one trained
seed) and reports when its end effector first enters the target, how long it stays, and the largest
joint displacement of each approach step as a fraction of that cap (near 1: the policy moves as fast
as the env allows, so arriving sooner needs a larger step or a stiffer servo, not a better policy).
"""

from __future__ import annotations

import argparse
import dataclasses
import json
import os

import numpy as np

import envs
from agents import evaluation, provenance

CAP_STEPS = 8
"""Env steps of full commanded steps in `servo_cap`; the displacement of the last half is the cap."""


def full_step_moves(env, num_envs: int, seed: int = 0) -> tuple[np.ndarray, np.ndarray]:
    """(|joint displacement| per env step (num_envs, CAP_STEPS, nq), start poses (num_envs, nq)): every joint
    commanded a full relative step (|action| = 1, towards the middle of its range, so the range never clips
    it) from the env's reset poses of `seed`."""
    import jax
    import jax.numpy as jnp

    low, high = env.robot.joint_low, env.robot.joint_high

    def run(key):
        state = env.reset(key)
        q0 = state.pipeline_state.qpos
        action = jnp.where(q0 < 0.5 * (low + high), 1.0, -1.0)

        def body(state, _):
            q = state.pipeline_state.qpos
            state = env.step(state, action)
            return state, jnp.abs(state.pipeline_state.qpos - q)

        return jax.lax.scan(body, state, None, length=CAP_STEPS)[1], q0

    moves, q0 = jax.jit(jax.vmap(run))(jax.random.split(jax.random.PRNGKey(seed), num_envs))
    return np.asarray(moves), np.asarray(q0)


def servo_cap(env, num_envs: int = 32, seed: int = 0) -> dict:
    """Per joint: the displacement (rad) of the first full commanded step from rest and the mean of the
    last `CAP_STEPS // 2` steps (moving), as numbers and as fractions of the commanded step (`relative_step`)."""
    if env.config.action != "relative":
        raise ValueError(f"env.action={env.config.action!r} is invalid for servo_cap: allowed is 'relative' "
                         "(absolute control has no per-step cap).")
    moves, _ = full_step_moves(env, num_envs, seed)
    first = moves[:, 0].mean(0).astype(float)
    moving = moves[:, CAP_STEPS // 2:].mean((0, 1)).astype(float)
    scale = env.config.relative_step(env.robot.joint_low, env.robot.joint_high)  # a number, or one per joint
    return {"action_scale": env.config.action_scale, "env_dt": float(env.dt), "num_envs": num_envs, "steps": CAP_STEPS,
            "first_step": first.round(4).tolist(), "moving_step": moving.round(4).tolist(),
            "moving_step_fraction_of_scale": (moving / scale).round(3).tolist(),
            "moving_speed_rad_s": (moving / env.dt).round(3).tolist()}


def policy_approach(policy, env_name: str, env, num_envs: int, cap: np.ndarray, unit: int = 0) -> dict:
    """First entry into the target, steps in it, and the approach's per-step joint motion against `cap`, of
    `policy` (an `agents.evaluation.Policy`) on `env` (registered as `env_name`)."""
    from agents import evaluation

    cfg = env.config
    rec = evaluation.rollout(policy, env_name, cfg, num_envs=num_envs, unit=unit)
    qpos, target, length = rec["qpos"], rec["target_pos"], rec["length"]
    ee = np.asarray(env.robot.kinematics(qpos).ee_pos)
    distance = np.linalg.norm(ee - target, axis=-1)  # (T + 1, n): after t steps
    inside = (distance < cfg.target_radius) & (np.arange(len(distance))[:, None] <= length[None, :])
    reached = inside.any(0)
    first = inside.argmax(0)
    if not reached.any():
        raise ValueError(f"checkpoint={policy.name!r} reached the target in none of {num_envs} episodes: allowed is a "
                         "policy that reaches it (an approach needs an arrival).")
    largest = (np.abs(np.diff(qpos, axis=0)) / cap).max(-1)  # (T, n): the fastest joint, as a fraction of its cap
    approach = np.concatenate([largest[:f, i] for i, f in enumerate(first) if reached[i] and f > 0] + [np.zeros(0)])
    entry = first[reached]
    return {"checkpoint": policy.name, "unit": unit, "env_name": env_name, "num_envs": num_envs,
            "episode_length": int(cfg.episode_length), "reached": float(reached.mean()),
            "first_entry_step": {"mean": float(entry.mean()), "median": float(np.median(entry)),
                                 "p10": float(np.percentile(entry, 10)), "p90": float(np.percentile(entry, 90))},
            "steps_in_target_reached": float(inside[:, reached].sum(0).mean()),
            "start_distance_reached": float(distance[0, reached].mean()),
            "approach_fastest_joint_fraction_of_cap": {
                "mean": float(approach.mean()), "median": float(np.median(approach)),
                "share_above_0.9": float((approach > 0.9).mean())},
            "median_distance_by_step": {int(t): float(np.median(distance[t, reached]))
                                        for t in (0, 10, 20, 30, 40, 50, 60, 80, 100) if t < len(distance)}}


def main(argv: list[str] | None = None) -> dict:
    parser = argparse.ArgumentParser(prog="python -m tools.approach_speed", description=__doc__.split("\n\n")[2])
    parser.add_argument("--checkpoint", help="a train.py logdir or export; its env and config unless --env")
    parser.add_argument("--env", help="registered env name (default: the checkpoint's)")
    parser.add_argument("--action-scale", type=float, help="the env's action_scale (default: the checkpoint's or "
                        "the env's); a policy evaluated at another scale than it trained with acts as trained")
    parser.add_argument("--num-envs", type=int, default=256)
    parser.add_argument("--unit", type=int, default=0, help="trained seed of the checkpoint (an index)")
    parser.add_argument("--json")
    args = parser.parse_args(argv)
    if not args.checkpoint and not args.env:
        parser.error("one of --checkpoint and --env is required")
    if args.checkpoint:
        policy = evaluation.checkpoint_policy(args.checkpoint)
        env_name = args.env or policy.train_env_name
        config = policy.train_env_config if env_name == policy.train_env_name else envs.default_config(env_name)
    else:
        env_name, config = args.env, envs.default_config(args.env)
    if args.action_scale is not None:
        config = dataclasses.replace(config, action_scale=args.action_scale)
    env = envs.from_config(env_name, config)  # checks the config
    made = provenance.stamp(provenance.command(None if argv is None else [__file__] + list(argv)))
    out = {"env_name": env_name, "env_config": dataclasses.asdict(config), **made, "cap": servo_cap(env)}
    print(f"{env_name}: action_scale {config.action_scale}; a full commanded step moves the joints "
          f"{out['cap']['moving_step']} rad per env step while moving "
          f"({out['cap']['moving_step_fraction_of_scale']} of the step)")
    if args.checkpoint:
        out["policy"] = policy_approach(policy, env_name, env, args.num_envs, np.asarray(out["cap"]["moving_step"]),
                                        args.unit)
        p = out["policy"]
        print(f"policy: reached {p['reached']:.1%}; first entry at step {p['first_entry_step']['median']:.0f} "
              f"(median; p10 {p['first_entry_step']['p10']:.0f}, p90 {p['first_entry_step']['p90']:.0f}); "
              f"{p['steps_in_target_reached']:.1f} steps in target over reached episodes; during the approach its "
              f"fastest joint moves {p['approach_fastest_joint_fraction_of_cap']['median']:.2f} of the cap (median), "
              f"above 0.9 of it in {p['approach_fastest_joint_fraction_of_cap']['share_above_0.9']:.0%} of the steps")
    if args.json:
        os.makedirs(os.path.dirname(os.path.abspath(args.json)), exist_ok=True)
        with open(args.json, "w") as f:
            json.dump(evaluation.jsonable(out), f, indent=2)
    return out


if __name__ == "__main__":
    main()
