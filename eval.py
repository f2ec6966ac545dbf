"""Evaluate a trained checkpoint or a baseline policy on any env configuration.

    python eval.py --env ur5e-reach --policy standstill --num-envs 64 --json out.json
    python eval.py --checkpoint runs/X --env.workspace full --json out.json      # newest checkpoint of a run
    python eval.py --checkpoint runs/X/checkpoints/2048000 runs/Y --csv out.csv  # a step, several runs
    python eval.py --checkpoint runs/R --env ur5e-reach-avoid --env.obstacle-radius 0.3  # reach agent, obstacle
    python eval.py --env panda-reach --policy pseudo_ik --num-envs 8 --video ik.mp4
    python eval.py --env ur5e-reach-avoid --policy mppi --planner.samples 64 --planner.horizon 16 --num-envs 512
    python eval.py --checkpoint runs/X --help                                     # also lists every --env.* option

What runs: `--num-envs` environments per evaluation seed (`--seeds` seeds from `--seed`, by default
the training driver's eval seed, so a run's own env config reproduces its eval.json), one episode
each, deterministic policy (`agents.loop.make_evaluate`; `--stochastic` samples the actions from the
policy's distribution instead, as in training). A checkpoint contributes one unit per
trained seed, a baseline one; the table gives mean ± sample std (ddof 1) over units (seeds / checkpoints); the JSON
also gives every unit's numbers and the std over all episodes. Metrics (the paper's): target
reached, self collision, obstacle collision, distance to the target (mean over the episode's last
10 steps), steps in target, times the target was left.

Env options: the env is `--env` (default: the checkpoint's); its config starts from the
checkpoint's stored env config (a baseline: the env's defaults) and `--env.<field> VALUE` replaces
fields, exactly as in train.py. A reach checkpoint may run on its robot's reach-avoid env (the
fields both tasks have come from the checkpoint, the obstacle's from the reach-avoid defaults). An
observation the network was not trained on is refused, naming both shapes; so are the trained parts
in another order and another action mode (relative / absolute), unless `--allow-env-mismatch`
(then a warning).

Physics: on a CPU the arm envs step with MuJoCo's C library (`--env.backend auto`, the default; no
physics to compile, far faster than MJX on a CPU), on a GPU with MJX; `--env.backend mjx` or
`mujoco` picks one (docs/environments.md, "Physics backends"). The JSON records which one ran.

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

Compare with the paper's baseline table under absolute control: its numbers are absolute
control's (results: baselines study). The distance column is each episode's own last 10 steps
(the paper's definition); the JSON's `distance_collided_as_0` is our reading of the paper's
evaluator, Brax's: an episode that ended in a collision counts as 0 m; `distance_reached` and
`steps_in_target_reached` are the precision of the episodes that reached the target only.

Planner (`agents.planner`): `--policy mppi` plans every step with the env itself as its model (MPPI:
`--planner.samples` sequences of `--planner.horizon` steps, weighted by return), a reference with a compute cost
(samples x horizon x iterations simulated env steps per env step, in the JSON as `model_steps_per_step`).
`--checkpoint PATH --shield` shields a trained policy with it (`agents.shield`): the policy acts unless its own
rollout of `--planner.horizon` steps in the model collides; then the first action of the best-return sampled sequence
(`--planner.samples`) that the model shows clear replaces it (horizon + samples x horizon x iterations model steps
per env step).

Video: `--video PATH` (.mp4 or .gif) renders the first `--video-envs` envs' first episodes (a grid)
with MuJoCo's offscreen renderer (`envs.render`; headless: EGL or OSMesa, chosen
automatically, or set MUJOCO_GL). Needs the `viz` extra (imageio, imageio-ffmpeg).

Compiled programs go to JAX's persistent compilation cache (`.jax_cache/` in the checkout, or
$JAX_COMPILATION_CACHE_DIR; set it empty for none): a second evaluation of a setting skips compiling, and, from
its traced programs kept in the cache's `programs/` folder (`agents.program_store`), tracing.
The JSON's `wall_seconds` says where the time went: before the evaluations (imports, devices, loading), in them
(compiling and running), and in all.

Exit codes: 0 done, 2 bad input (a one-line `error:` message: missing or corrupt checkpoint,
another robot, unknown policy or option).
"""

from __future__ import annotations

import csv
import dataclasses
import importlib.util
import json
import os
import shlex
import sys
import time
from typing import Annotated, Generic, TypeVar

IMPORTED = time.perf_counter()
"""When this module started importing the project (and jax, MuJoCo, MJX): the JSON's `wall_seconds` count from here."""

import tyro  # noqa: E402

import envs  # noqa: E402
from agents import baselines, evaluation, intervals, planner as planners, program_store, provenance, xla_flags  # noqa: E402
from agents import logdir as logdirs  # noqa: E402
from tools import run_cli  # noqa: E402

EnvConfigT = TypeVar("EnvConfigT")


@dataclasses.dataclass(frozen=True)
class NoEnvOptions:
    """Stands for the env's config until the env is known (`--env` or the checkpoint's)."""


@dataclasses.dataclass(frozen=True)
class EvalConfig(Generic[EnvConfigT]):
    """Evaluate a checkpoint or a baseline policy on any env configuration (`eval.py --help` with
    --env NAME or --checkpoint PATH also lists the env's options, --env.<field> VALUE)."""

    env: EnvConfigT
    """The env's config: starts from the checkpoint's stored one (a baseline: the env's defaults);
    `--env.<field> VALUE` replaces fields."""
    checkpoint: Annotated[tuple[str, ...], tyro.conf.arg(metavar="PATH [PATH ...]")] = ()
    """What to evaluate (or --policy): train.py logdirs (their newest checkpoint), checkpoint step
    directories or policy export directories, evaluated one after the other."""
    policy: Annotated[str | None, tyro.conf.arg(metavar="NAME")] = None
    """What to evaluate (or --checkpoint): a baseline, one of random, standstill, pseudo_ik, or the planner, mppi."""
    planner: planners.PlannerConfig = planners.PlannerConfig()
    """The planner's options (with --policy mppi or --shield)."""
    shield: bool = False
    """Shield each checkpoint's policy with the planner's model (`agents.shield`): the policy acts unless its own
    rollout of --planner.horizon steps in the model collides, then the best sampled sequence the model shows clear."""
    env_name: Annotated[str | None, tyro.conf.arg(name="env", metavar="NAME")] = None
    """Registered env name; None: the checkpoint's env."""
    num_envs: int = 4096
    """Environments (= episodes) per evaluation seed."""
    seeds: int = 1
    """Evaluation seeds, each a fresh set of episodes."""
    seed: int = evaluation.DEFAULT_EVAL_SEED
    """First evaluation seed; the default is the training driver's eval seed."""
    stochastic: bool = False
    """Sample a checkpoint's actions from its policy's distribution instead of taking the mode."""
    allow_env_mismatch: bool = False
    """Evaluate a checkpoint with another observation layout (the same parts reordered) or action
    mode than it was trained with, or where an observed part it saw at one value in training changes
    (agents.evaluation.unseen_constants), warning instead of refusing (its network reads and acts as trained)."""
    compute_dtype: Annotated[str | None, tyro.conf.arg(metavar="DTYPE")] = None
    """Hidden layers of a SAC checkpoint's policy in float32 or bfloat16 for this evaluation (None: as trained)."""
    last_steps: int = 10
    """Steps the final distance is averaged over."""
    json: Annotated[str | None, tyro.conf.arg(metavar="PATH")] = None
    """Write every number and the full configuration as JSON."""
    csv: Annotated[str | None, tyro.conf.arg(metavar="PATH")] = None
    """Write one row per unit (policy seed x eval seed) as CSV."""
    video: Annotated[str | None, tyro.conf.arg(metavar="PATH")] = None
    """Render a rollout to PATH (.mp4 or .gif)."""
    video_envs: int = 1
    """Envs shown in the video, as a grid."""
    video_size: Annotated[str, tyro.conf.arg(metavar="WIDTHxHEIGHT")] = "480x360"
    """Pixels per env in the video."""
    force: bool = False
    """Replace an existing --json, --csv or --video file (a run's or an export's own files are never replaced)."""


POLICIES = baselines.BASELINES + (planners.NAME,)
"""What --policy names: the baselines and the planner."""


def parse(argv: list[str], base=None, show_help: bool = False) -> EvalConfig:
    """`argv` parsed by tyro over `EvalConfig` with `base` as the env config's defaults (None: the
    env options are left for a second call, once the env is known). `show_help`: prints the help and
    exits 0. Unknown options: ValueError; bad values: tyro's message, exit code 2."""
    config_cls = NoEnvOptions if base is None else type(base)
    default = EvalConfig(env=NoEnvOptions() if base is None else base)
    parsed, unknown = tyro.cli(EvalConfig[config_cls], default=default, args=["--help"] if show_help else argv,
                               return_unknown_args=True, prog="eval.py")
    if base is not None and unknown:
        raise ValueError(f"option {unknown[0]!r} is unknown: allowed are eval.py's options (--help) and --env.<field>.")
    return parsed


def check(args: EvalConfig) -> None:
    """ValueError naming the option, its value and what is allowed (before anything is loaded)."""
    if bool(args.checkpoint) == bool(args.policy):
        raise ValueError("give exactly one of --checkpoint PATH... and --policy NAME (allowed policies: "
                         f"{', '.join(POLICIES)}).")
    if args.policy is not None and args.policy not in POLICIES:
        raise ValueError(f"--policy={args.policy!r} is unknown: allowed are {', '.join(POLICIES)}.")
    if args.shield and args.policy:
        raise ValueError(f"--shield is invalid with --policy {args.policy}: allowed only with --checkpoint (a baseline "
                         "or the planner has no policy of its own to shield).")
    if args.planner != planners.PlannerConfig() and args.policy != planners.NAME and not args.shield:
        raise ValueError(f"--planner.* options are invalid with {'--policy ' + args.policy if args.policy else '--checkpoint'}:"
                         f" allowed only with --policy {planners.NAME} or --checkpoint PATH --shield.")
    for name in ("num_envs", "seeds", "last_steps", "video_envs"):
        if getattr(args, name) < 1:
            raise ValueError(f"--{name.replace('_', '-')}={getattr(args, name)} is invalid: allowed is an integer >= 1.")
    if args.video:
        _video_size(args.video_size)
        if not args.video.lower().endswith((".mp4", ".gif")):
            raise ValueError(f"--video={args.video!r} is invalid: allowed are .mp4 and .gif files.")
        needed = ("imageio", "imageio_ffmpeg") if args.video.lower().endswith(".mp4") else ("imageio",)
        missing = [name for name in needed if importlib.util.find_spec(name) is None]
        if missing:
            raise ValueError(f"--video={args.video!r} needs {' and '.join(missing)}: pip install -e '.[viz]'")
    for option in ("json", "csv", "video"):
        if getattr(args, option):
            check_output(f"--{option}", getattr(args, option), args.force)
    if args.stochastic and args.shield:
        raise ValueError("--stochastic is invalid with --shield: allowed only without --stochastic (the shield checks "
                         "the policy's deterministic rollout).")
    if args.stochastic and args.policy:
        raise ValueError(f"--stochastic is invalid with --policy {args.policy}: allowed only with --checkpoint (the "
                         "baselines and the planner have no action distribution).")
    if args.compute_dtype is not None and args.compute_dtype not in evaluation.COMPUTE_DTYPES:
        raise ValueError(f"--compute-dtype={args.compute_dtype!r} is invalid: allowed are "
                         f"{', '.join(evaluation.COMPUTE_DTYPES)}.")
    if args.compute_dtype and args.policy:
        raise ValueError(f"--compute-dtype is invalid with --policy {args.policy}: allowed only with --checkpoint (the "
                         "baselines and the planner have no network).")
    if args.policy and not args.env_name:
        raise ValueError("--policy needs --env NAME (allowed: " + ", ".join(envs.names()) + ").")


def main(argv: list[str] | None = None) -> list:
    argv = list(sys.argv[1:] if argv is None else argv)
    wants_help = any(a in ("-h", "--help") for a in argv)
    args = parse([a for a in argv if a not in ("-h", "--help")])
    if wants_help and not (args.env_name or args.checkpoint):
        parse([], show_help=True)  # eval.py's options; the env's need the env
    if not wants_help:
        check(args)
    if args.checkpoint:
        policies = [evaluation.with_compute_dtype(evaluation.checkpoint_policy(path), args.compute_dtype)
                    for path in args.checkpoint]
        if args.shield:
            policies = [evaluation.shielded_policy(policy, args.planner) for policy in policies]
    elif args.policy == planners.NAME:
        policies = [evaluation.planner_policy(args.planner)]
    else:
        policies = [evaluation.baseline_policy(args.policy or "standstill")]
    env_name = args.env_name or policies[0].train_env_name
    spec = envs.registry.spec(env_name)  # unknown name -> ValueError listing the names
    if args.video and spec.robot is None:
        raise ValueError(f"--video needs an arm env: {env_name!r} has no robot model to render.")
    bases = [envs.make_config(env_name, policy.train_env_config) for policy in policies]
    if wants_help:
        parse([], bases[0], show_help=True)  # every option, the env's included
    # Each checkpoint's own env config with the --env.<field> options replacing fields.
    configs = [parse(argv, base).env for base in bases]  # checked by evaluation.check below
    overrides = {f.name: getattr(config, f.name) for base, config in zip(bases, configs)
                 for f in dataclasses.fields(config) if getattr(config, f.name) != getattr(base, f.name)}
    eval_seeds = [args.seed + i for i in range(args.seeds)]

    for policy, config in zip(policies, configs):  # every bad combination refused before anything runs
        evaluation.check(policy, env_name, config, args.allow_env_mismatch)
    if sum(len(policy.units) for policy in policies) * len(eval_seeds) > 1:
        intervals.check_installed()  # intervals over the units come after the evaluations
    results, first_evaluation = [], time.perf_counter()
    for i, (policy, config) in enumerate(zip(policies, configs)):
        trained = f"{len(policy.units)} trained seed(s) x " if policy.export else ""
        _progress(f"[{i + 1}/{len(policies)}] {policy.name} on {env_name}: {trained}{len(eval_seeds)} eval seed(s) x "
                  f"{args.num_envs} episodes")
        results.append(evaluation.run(policy, env_name, config, args.num_envs, eval_seeds, args.last_steps,
                                      stochastic=args.stochastic, progress=lambda line: _progress("  " + line),
                                      allow_env_mismatch=args.allow_env_mismatch))

    command = "python eval.py " + " ".join(shlex.quote(a) for a in argv)
    print(evaluation.markdown(results))
    print(f"\n{env_name}, overrides {overrides or 'none'}; eval seeds {eval_seeds}; device {provenance.device_description()}")
    report = {
        **provenance.stamp(command),  # command, code, device, date
        "env_name": env_name,
        "env_overrides": {k: (list(v) if isinstance(v, tuple) else v) for k, v in overrides.items()},
        "num_envs": args.num_envs,
        "eval_seeds": eval_seeds,
        "evaluations": [r.to_json() for r in results],
        "pooled": evaluation.pooled(results) if len(results) > 1 else None,
        "wall_seconds": {  # where a run's time goes: start-up (imports, devices, loading), evaluations, the rest
            "before_evaluations": round(first_evaluation - IMPORTED, 2),
            "evaluations": round(sum(r.seconds for r in results), 2),
            "total": round(time.perf_counter() - IMPORTED, 2)},
    }
    if args.json:
        _replace_atomically(args.json, lambda f: json.dump(evaluation.jsonable(report), f, indent=2, allow_nan=False))
    if args.csv:
        _write_csv(args.csv, results)
    if args.video:
        _progress(f"rendering the first episode of {args.video_envs} env(s) to {args.video} ...")
        write_video(args.video, policies[0], env_name, configs[0], args.video_envs, args.seed, args.video_size,
                    stochastic=args.stochastic, allow_env_mismatch=args.allow_env_mismatch)
        _progress(f"video: {args.video}")
    return results


def _progress(line: str) -> None:
    """Progress goes to stderr; stdout holds the results table."""
    print(line, file=sys.stderr, flush=True)


def run_file_owner(path: str) -> str | None:
    """The train.py run or policy export that `path` would write into, or None: any file of an export
    directory, a run's own files (agents.logdir.RUN_FILES) and anything under its checkpoints/ or tb/."""
    path = os.path.abspath(path)
    parent = os.path.dirname(path)
    if os.path.isfile(os.path.join(parent, "policy.json")) or os.path.isfile(os.path.join(parent, "policy.npz")):
        return f"the policy export {parent}"
    child, folder = path, parent
    while folder != os.path.dirname(folder):
        is_run = os.path.isfile(os.path.join(folder, "config.json")) or os.path.isdir(os.path.join(folder, "checkpoints"))
        if is_run and os.path.basename(child) in logdirs.RUN_FILES:
            return f"the run {folder}"
        child, folder = folder, os.path.dirname(folder)
    return None


def check_output(option: str, path: str, force: bool) -> None:
    """ValueError before any work for an output path that would fail or destroy something: a directory, a
    run's or an export's own file, an existing file without --force, or a folder that cannot be written."""
    owner = run_file_owner(path)
    if owner:
        raise ValueError(f"{option}={path!r} is a file of {owner}: allowed is a path outside it (e.g. beside the run).")
    if os.path.isdir(path):
        raise ValueError(f"{option}={path!r} is a directory: allowed is a file path.")
    if os.path.exists(path) and not force:
        raise ValueError(f"{option}={path!r} exists: allowed are a new path, or --force to replace it.")
    folder = os.path.dirname(os.path.abspath(path))
    while not os.path.exists(folder):
        folder = os.path.dirname(folder)
    if not os.path.isdir(folder) or not os.access(folder, os.W_OK | os.X_OK):
        raise ValueError(f"{option}={path!r} cannot be written ({folder} is not a writable directory): allowed is a "
                         "path in a folder you can write to.")


def _replace_atomically(path: str, write) -> None:
    """`write(file)` into a temporary file beside `path`, then renames it over `path`: a failure leaves the old one."""
    _makedirs_for(path)
    temporary = f"{path}.tmp-{os.getpid()}"
    try:
        with open(temporary, "w", newline="") as f:
            write(f)
        os.replace(temporary, path)
    finally:
        if os.path.exists(temporary):
            os.remove(temporary)


def _makedirs_for(path: str) -> None:
    if os.path.dirname(path):
        os.makedirs(os.path.dirname(path), exist_ok=True)


def _write_csv(path: str, results) -> None:
    names = sorted({n for r in results for u in r.units for n in u["metrics"]})

    def write(f):
        w = csv.writer(f)
        w.writerow(["policy", "env_name", "env_config", "num_envs", "policy_seed", "eval_seed"] + names)
        for r in results:
            cfg = json.dumps(dataclasses.asdict(r.env_config), sort_keys=True)
            for u in r.units:
                w.writerow([r.policy.name, r.env_name, cfg, r.num_envs, u["policy_seed"], u["eval_seed"]]
                           + [u["metrics"].get(n, "") for n in names])

    _replace_atomically(path, write)


def _video_size(size: str) -> tuple[int, int]:
    try:
        width, height = (int(v) for v in size.lower().split("x"))
        if width < 16 or height < 16:
            raise ValueError
    except ValueError:
        raise ValueError(f"--video-size={size!r} is invalid: allowed is WIDTHxHEIGHT (each >= 16), e.g. 480x360.") from None
    return width, height


def write_video(path: str, policy, env_name: str, env_config, num_envs: int, seed: int, size: str = "480x360",
                stochastic: bool = False, allow_env_mismatch: bool = False) -> None:
    """Renders each of `num_envs` envs' first episode (a grid of views) to an mp4 or gif, with the
    actions the evaluation took (sampled with `stochastic`)."""
    from envs import render

    width, height = _video_size(size)
    env = envs.from_config(env_name, env_config)
    records = evaluation.rollout(policy, env_name, env_config, num_envs, seed, stochastic=stochastic,
                                 allow_env_mismatch=allow_env_mismatch)
    frames = render.rollout_frames(env, records, width=width, height=height)
    _makedirs_for(path)
    render.write_video(path, frames, fps=round(1.0 / env.dt))


if __name__ == "__main__":
    cache = xla_flags.compilation_cache()  # a second evaluation of the same setting loads its program instead of compiling
    program_store.use(os.path.join(cache, "programs") if cache else None)  # ... and skips tracing it
    run_cli(main)
