"""Evaluate a trained checkpoint or a baseline policy on any env configuration.

    python eval.py --env ur5e-reach --policy standstill --num-envs 64 --json out.json
    python eval.py --checkpoint runs/X --env.workspace full --json out.json      # newest checkpoint of a run
    python eval.py --checkpoint runs/X/checkpoints/2048000 runs/Y --csv out.csv  # a step, several runs
    python eval.py --checkpoint runs/R --env ur5e-reach-avoid --env.obstacle-radius 0.3  # reach agent, obstacle
    python eval.py --env panda-reach --policy pseudo_ik --num-envs 8 --video ik.mp4
    python eval.py --checkpoint runs/X --help                                     # also lists every --env.* option

What runs: `--num-envs` environments per evaluation seed (`--seeds` seeds from `--seed`, by default
the training driver's eval seed, so a run's own env config reproduces its eval.json), one episode
each, deterministic policy (`agents.loop.make_evaluate`; `--stochastic` samples the actions from the
policy's distribution instead, as in training). A checkpoint contributes one unit per
trained seed, a baseline one; the table gives mean ± std over units (seeds / checkpoints); the JSON
also gives every unit's numbers and the std over all episodes. Metrics (the paper's): target
reached, self collision, obstacle collision, distance to the target (mean over the episode's last
10 steps), steps in target, times the target was left.

Env options: the env is `--env` (default: the checkpoint's); its config starts from the
checkpoint's stored env config (a baseline: the env's defaults) and `--env.<field> VALUE` replaces
fields, exactly as in train.py. A reach checkpoint may run on its robot's reach-avoid env (the
fields both tasks have come from the checkpoint, the obstacle's from the reach-avoid defaults). An
observation the network was not trained on is refused, naming both shapes.

Checkpoints: eval.py loads the small policy export (`agents.export`: policy parameters, observation
statistics, config) that the training driver writes next to each checkpoint; it never builds the
training programs or reads the optimiser state or replay buffer. `--checkpoint` takes a train.py
logdir (its newest checkpoint), a checkpoint step directory or an export directory (e.g. one under
results/checkpoints/). A checkpoint from before exports existed gets one written first.

Baselines (`agents.baselines`; paper, "Baselines"): `random` (uniform actions in the env's action
space), `standstill` (commands its initial pose), `pseudo_ik` (commands `info["target_qpos"]`, the
pose whose forward kinematics produced the target; needs target_sampling="reachable"). standstill
and pseudo_ik command a joint configuration, which maps onto both action modes (absolute: its
action; relative: the clipped step towards it); random means something else in each mode.

Against the paper's UR5e baseline table (full workspace, reach, 125 steps; see
results/baselines/baselines.md for our numbers and their commands):
{FINDINGS}

Video: `--video PATH` (.mp4 or .gif) renders the first `--video-envs` envs' first episodes (a grid)
with MuJoCo's offscreen renderer (`benchmarks.render`; headless: EGL or OSMesa, chosen
automatically, or set MUJOCO_GL). Needs the `viz` extra (imageio, imageio-ffmpeg).

Exit codes: 0 done, 2 bad input (a one-line `error:` message: missing or corrupt checkpoint,
another robot, unknown policy or option).
"""

from __future__ import annotations

import argparse
import csv
import dataclasses
import importlib.util
import json
import os
import shlex
import sys
from typing import Generic, TypeVar

ROOT = os.path.dirname(os.path.abspath(__file__))
if ROOT not in sys.path:
    sys.path.insert(0, ROOT)

FINDINGS = """\
- Action mode. The paper's baselines ran with absolute position control. Random actions under
  relative control are a small random walk: 5.0 % self-collision and 0.871 m, the standstill's
  distance; under absolute control the arm flails around the middle of its range: 22.4 % and
  0.978 m, above the standstill as in the paper (30 %, 0.929 m vs 0.855 m). The pseudo-IK under
  relative control (measured with action_scale 0.1, the default then) moves its servo target only
  0.1 rad per step, the arm creeps and 0.6 % reach the 1 cm target; under absolute control 41.5 %
  (paper 36.9 %).
- Ours vs the paper, absolute control, 5 seeds x 4096 envs (GPU; a CPU run of the first 64 episodes
  gives identical numbers): random 0.000 / 0.224 / 0.978 m (paper 0.000 / 0.300 / 0.929 m);
  standstill 0 / 0.001 / 0.870 m (paper 0 / 0 / 0.855 m); pseudo-IK 0.415 (1 cm) and 0.570
  (2 cm) reached, 0.332 self-collision, 0.272 m (paper 0.369, 0.510, 0.222, 0.033 m).
- The distance column: the paper's pseudo-IK 0.033 m is what ours gives when episodes that ended
  in a collision count as 0 m (0.036 m; collision-free episodes alone: 0.050 m; all episodes,
  each at its last 10 steps: 0.272 m). Brax's evaluator (brax.envs.wrappers.training.EvalWrapper),
  which the paper used, sums each per-step metric over an episode's active steps; an env that
  records the distance only over the last 10 of the 125 steps thus scores 0 for an episode that
  collided earlier (our reading; the paper's env code is not public). We report the distance over every episode's own last 10 steps (the
  paper's definition) and give the collided-as-0 reading in results/baselines/baselines.md. For the random
  agent that reading is 0.783 m, further from the paper's 0.929 m than ours: unexplained.
- Standstill collides in 0.07 % of episodes: initial poses are rejected only if already in
  contact, and a pose within millimetres of contact sags under gravity (the servos' steady-state
  error) into it within 7 steps. The paper rounds its rate to 0.000.
- Collision rates (random 22 vs 30 %, pseudo-IK 33 vs 22 %) depend on how fast each joint follows
  its target, which sets the joint-space path: our joint damping is tuned so the peak speeds stay
  within the official limits (assets/README.md); the paper added damping too, with values it does
  not give. Collision geometry differs as well (our capsules, base sphere and 18 checked pairs,
  tested after every 2 ms substep, against the paper's MJX contacts).
- The zero relative action is no standstill: it re-targets the sagged pose every step, and the
  UR5e's end effector drops 0.10 m (median; 2 % collide), the Panda's 0.67 m (13 % collide)."""

__doc__ = __doc__.replace("{FINDINGS}", FINDINGS)

ConfigT = TypeVar("ConfigT")


@dataclasses.dataclass(frozen=True)
class EnvOptions(Generic[ConfigT]):
    """Environment options (fields of the env's config dataclass)."""

    env: ConfigT
    """The env config: starts from the checkpoint's stored one (baselines: the env's defaults)."""


def _parser() -> argparse.ArgumentParser:
    p = argparse.ArgumentParser(
        prog="eval.py", add_help=False, allow_abbrev=False,
        description="Evaluate a checkpoint or a baseline on any env configuration (--env.<field> VALUE overrides).")
    what = p.add_argument_group("what to evaluate (one of)")
    what.add_argument("--checkpoint", nargs="+", action="extend", default=[], metavar="PATH",
                      help="train.py logdir (newest checkpoint), checkpoint step directory or policy export "
                           "directory; several are evaluated one after the other")
    what.add_argument("--policy", help="a baseline: random, standstill, pseudo_ik")
    p.add_argument("--env", help="registered env name (default: the checkpoint's env)")
    p.add_argument("--num-envs", type=int, default=4096, help="environments (= episodes) per seed (default 4096)")
    p.add_argument("--seeds", type=int, default=1, help="evaluation seeds, each a fresh set of episodes (default 1)")
    p.add_argument("--seed", type=int, default=1_000_000,
                   help="first evaluation seed (default: the training driver's eval seed)")
    p.add_argument("--stochastic", action="store_true",
                   help="sample a checkpoint's actions from its policy's distribution instead of taking the mode")
    p.add_argument("--last-steps", type=int, default=10, help="steps the final distance is averaged over (default 10)")
    p.add_argument("--json", metavar="PATH", help="write every number and the full configuration as JSON")
    p.add_argument("--csv", metavar="PATH", help="write one row per unit (policy seed x eval seed) as CSV")
    p.add_argument("--video", metavar="PATH", help="render a rollout to PATH (.mp4 or .gif)")
    p.add_argument("--video-envs", type=int, default=1, help="envs shown in the video, as a grid (default 1)")
    p.add_argument("--video-size", default="480x360", help="pixels per env, WIDTHxHEIGHT (default 480x360)")
    p.add_argument("-h", "--help", action="store_true", help="show this help (with --env or --checkpoint: also the "
                                                             "--env.* options) and exit")
    return p


def _given_fields(tokens: list[str], config) -> list[str]:
    """Config fields named by `--env.<field>` tokens (tyro's `--env.no-<field>` included)."""
    names = {f.name for f in dataclasses.fields(config)}
    given = []
    for token in tokens:
        if not token.startswith("--env."):
            continue
        name = token[len("--env."):].split("=", 1)[0].replace("-", "_")
        if name not in names and name.startswith("no_") and name[3:] in names:
            name = name[3:]
        given.append(name)
    return given


def _is_number(token: str) -> bool:
    try:
        float(token)
        return True
    except ValueError:
        return False


def parse_env_options(env_name: str, base, tokens: list[str], help_only: bool = False) -> dict:
    """{field: value} of the `--env.*` tokens, parsed by tyro over the env's config dataclass with
    `base` as defaults (bad values: tyro's message, exit code 2)."""
    import tyro

    if help_only:
        tokens = ["--help"]
    else:
        for token in tokens:
            if token.startswith("-") and not token.startswith("--env.") and not _is_number(token):
                raise ValueError(f"option {token!r} is unknown: allowed are eval.py's options (--help) and --env.<field>.")
    parsed = tyro.cli(EnvOptions[type(base)], default=EnvOptions(base), args=tokens, prog=f"eval.py --env {env_name}",
                      description=f"Options of env {env_name!r}, starting from {'the checkpoint' if base else 'defaults'}.")
    return {name: getattr(parsed.env, name) for name in _given_fields(tokens, base)}


def main(argv: list[str] | None = None) -> list:
    argv = list(sys.argv[1:] if argv is None else argv)
    args, rest = _parser().parse_known_args(argv)
    if args.help and not (args.env or args.checkpoint):
        _parser().print_help()
        print("\nEnv options: --env.<field> VALUE (`eval.py --env NAME --help` lists them).")
        raise SystemExit(0)

    import envs
    from agents import evaluation

    if bool(args.checkpoint) == bool(args.policy) and not args.help:
        raise ValueError("give exactly one of --checkpoint PATH... and --policy NAME (allowed policies: "
                         "random, standstill, pseudo_ik).")
    for name in ("num_envs", "seeds", "last_steps", "video_envs"):
        if getattr(args, name) < 1:
            raise ValueError(f"--{name.replace('_', '-')}={getattr(args, name)} is invalid: allowed is an integer >= 1.")
    if args.video:
        _video_size(args.video_size)
        if not args.video.lower().endswith((".mp4", ".gif")):
            raise ValueError(f"--video={args.video!r} is invalid: allowed are .mp4 and .gif files.")
        if importlib.util.find_spec("imageio") is None:
            raise ValueError("--video needs imageio (and imageio-ffmpeg for .mp4): pip install -e '.[viz]'")
    if args.stochastic and args.policy:
        raise ValueError(f"--stochastic is invalid with --policy {args.policy}: allowed only with --checkpoint (the "
                         "baselines have no action distribution).")
    if args.checkpoint:
        policies = [evaluation.checkpoint_policy(path) for path in args.checkpoint]
    else:
        if not args.env:
            raise ValueError("--policy needs --env NAME (allowed: " + ", ".join(envs.names()) + ").")
        policies = [evaluation.baseline_policy(args.policy or "standstill")]
    env_name = args.env or policies[0].train_env_name
    envs.registry.spec(env_name)  # unknown name -> ValueError listing the names

    if args.video and evaluation.robot_of(env_name) == env_name:
        raise ValueError(f"--video needs an arm env: {env_name!r} has no robot model to render.")
    first_base = evaluation.env_config_for(env_name, policies[0].train_env_config)
    if args.help:
        _parser().print_help()
        parse_env_options(env_name, first_base, [], help_only=True)  # prints tyro's help, exits 0
    overrides = parse_env_options(env_name, first_base, rest)
    eval_seeds = [args.seed + i for i in range(args.seeds)]

    configs = [evaluation.env_config_for(env_name, policy.train_env_config, **overrides) for policy in policies]
    for policy, config in zip(policies, configs):  # every bad combination refused before anything runs
        evaluation.check(policy, env_name, config)
    results = []
    for policy, config in zip(policies, configs):
        print(f"evaluating {policy.name} on {env_name} ({len(policy.units)} x {len(eval_seeds)} unit(s) x "
              f"{args.num_envs} envs) ...", file=sys.stderr, flush=True)
        results.append(evaluation.run(policy, env_name, config, args.num_envs, eval_seeds, args.last_steps,
                                      stochastic=args.stochastic))

    command = "python eval.py " + " ".join(shlex.quote(a) for a in argv)
    print(evaluation.markdown(results))
    print(f"\n{env_name}, overrides {overrides or 'none'}; eval seeds {eval_seeds}; device {evaluation.device_description()}")
    report = {
        "command": command,
        "device": evaluation.device_description(),
        "code": evaluation.code_version(),
        "env_name": env_name,
        "env_overrides": {k: (list(v) if isinstance(v, tuple) else v) for k, v in overrides.items()},
        "num_envs": args.num_envs,
        "eval_seeds": eval_seeds,
        "evaluations": [r.to_json() for r in results],
        "pooled": evaluation.pooled(results) if len(results) > 1 else None,
    }
    if args.json:
        _makedirs_for(args.json)
        with open(args.json, "w") as f:
            json.dump(evaluation.jsonable(report), f, indent=2, allow_nan=False)
    if args.csv:
        _write_csv(args.csv, results)
    if args.video:
        write_video(args.video, policies[0], env_name, configs[0], args.video_envs, args.seed, args.video_size,
                    stochastic=args.stochastic)
        print(f"video: {args.video}", file=sys.stderr)
    return results


def _makedirs_for(path: str) -> None:
    if os.path.dirname(path):
        os.makedirs(os.path.dirname(path), exist_ok=True)


def _write_csv(path: str, results) -> None:
    _makedirs_for(path)
    names = sorted({n for r in results for u in r.units for n in u["metrics"]})
    with open(path, "w", newline="") as f:
        w = csv.writer(f)
        w.writerow(["policy", "env_name", "env_config", "num_envs", "policy_seed", "eval_seed"] + names)
        for r in results:
            cfg = json.dumps(dataclasses.asdict(r.env_config), sort_keys=True)
            for u in r.units:
                w.writerow([r.policy.name, r.env_name, cfg, r.num_envs, u["policy_seed"], u["eval_seed"]]
                           + [u["metrics"].get(n, "") for n in names])


def _video_size(size: str) -> tuple[int, int]:
    try:
        width, height = (int(v) for v in size.lower().split("x"))
        if width < 16 or height < 16:
            raise ValueError
    except ValueError:
        raise ValueError(f"--video-size={size!r} is invalid: allowed is WIDTHxHEIGHT (each >= 16), e.g. 480x360.") from None
    return width, height


def write_video(path: str, policy, env_name: str, env_config, num_envs: int, seed: int, size: str = "480x360",
                stochastic: bool = False) -> None:
    """Renders each of `num_envs` envs' first episode (a grid of views) to an mp4 or gif, with the
    actions the evaluation took (sampled with `stochastic`)."""
    from agents import evaluation
    from benchmarks import render

    width, height = _video_size(size)
    import envs

    env = envs.from_config(env_name, env_config)
    records = evaluation.rollout(policy, env_name, env_config, num_envs, seed, stochastic=stochastic)
    frames = render.rollout_frames(env, records, width=width, height=height)
    _makedirs_for(path)
    render.write_video(path, frames, fps=round(1.0 / env.dt))


if __name__ == "__main__":
    try:
        main()
    except ValueError as error:
        print(f"error: {error}", file=sys.stderr)
        raise SystemExit(2)
