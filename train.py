"""Train PPO or SAC on a registered environment from a named preset.

    python train.py point-mass-ppo
    python train.py point-mass-ppo --seeds 5 --num-timesteps 300000 --env.goal-radius 0.05
    python train.py ur5e-reach-ppo --algo.learning-rate 3e-4 --logdir runs/lr3e-4
    python train.py ur5e-reach-ppo --logdir runs/lr3e-4 --resume          # continue a run, with its stored options
    python train.py ur5e-reach-ppo --logdir runs/lr3e-4 --overwrite       # delete that run, start afresh
    python train.py point-mass-sac --help                                 # every option

Every option comes from the config dataclasses (`agents.config.TrainConfig`, the algorithm's
config and the environment's config), so `--help` lists each with its docstring. The presets are
in `agents/presets.py`.

Compiled programs go to JAX's persistent compilation cache (`.jax_cache/` in the checkout, or
$JAX_COMPILATION_CACHE_DIR; set it empty for none), so a rerun or resume of a setting skips compiling.

Exit codes: 0 done (or stopped by --stop-after-steps / --stop-after-seconds), 1 a non-finite learner
metric or a failed write, 2 bad input (a one-line `error:` message), 130 stopped by Ctrl-C (after its checkpoint).
"""

from __future__ import annotations

import os
import sys

import jax

from agents import xla_flags
from agents.config import TrainConfig, adopt_saved_config, read_config
from agents.driver import NonFiniteLossError, train
from agents.logger import summary_lines
from agents.presets import PRESETS, make_config


def parse(argv: list[str]) -> TrainConfig:
    """Preset name first, then tyro-generated options. Not validated here: `agents.train` validates every config
    it is given (ValueError) before anything is written or compiled."""
    if not argv or argv[0] in ("-h", "--help"):
        lines = [f"  {name:26s} {p.description}" for name, p in sorted(PRESETS.items())]
        print("usage: train.py PRESET [OPTIONS]   (train.py PRESET --help lists the options)\n\npresets:\n" + "\n".join(lines))
        raise SystemExit(0)
    import tyro

    config = make_config(argv[0])
    cls = TrainConfig[type(config.env), type(config.algo)]
    config = tyro.cli(cls, default=config, args=argv[1:], prog=f"train.py {argv[0]}",
                      description=PRESETS[argv[0]].description)
    saved_path = os.path.join(config.logdir, "config.json")
    if config.resume and config.logdir and os.path.isfile(saved_path):  # no logdir: the run refuses --resume
        config = adopt_saved_config(config, read_config(saved_path), explicit_fields(argv[1:]))
    return config


def explicit_fields(args: list[str]) -> set[str]:
    """Dotted config field names that command-line options set: "--algo.learning-rate 3e-4" gives
    "algo.learning_rate", "--no-progress" gives "progress"."""
    names = set()
    for arg in args:
        if arg.startswith("--") and len(arg) > 2:
            *path, last = arg[2:].split("=", 1)[0].replace("_", "-").split(".")  # tyro takes both spellings
            last = last[3:] if last.startswith("no-") else last
            names.add(".".join(path + [last]).replace("-", "_"))
    return names


def main(argv: list[str] | None = None):
    config = parse(sys.argv[1:] if argv is None else argv)
    result = train(config)
    print(f"{result.status} after {result.env_steps:,} env steps; logs and checkpoints in {result.logdir}")
    if result.status == "stopped":
        print(f"stopped before num_timesteps: continue with `python train.py {config.preset} --resume --logdir "
              f"{result.logdir}`")
    if result.note:
        print(result.note)
    if result.eval_metrics:
        print(f"evaluation, deterministic policy, {config.eval_envs} episodes per seed (mean over seeds):")
        print("\n".join(summary_lines(result.eval_metrics)))
    print(next_steps(result.logdir, jax.default_backend()))
    return result


def next_steps(logdir: str, backend: str) -> str:
    """What to run next: an evaluation sized for this machine (a CPU runs 64 envs in about a minute; the
    default 4,096 are for a GPU) and TensorBoard, which its own extra installs."""
    envs_flag = "" if backend == "gpu" else " --num-envs 64"
    return (f"next: python eval.py --checkpoint {logdir}{envs_flag}   |   tensorboard --logdir {logdir} "
            f"(pip install -e \".[tensorboard]\")")


INTERRUPTED = 130
"""Exit code of a run stopped by Ctrl-C (the shell's 128 + SIGINT), so scripts can tell it from a finished one."""


def cli(argv: list[str] | None = None) -> int:
    """`main` with the exit code: one-line `error:` messages instead of tracebacks."""
    try:
        result = main(argv)
    except ValueError as error:
        print(f"error: {error}", file=sys.stderr)
        return 2
    except NonFiniteLossError as error:
        print(f"error: {error}", file=sys.stderr)
        return 1
    except OSError as error:  # a write that failed mid-run (disk full, permissions changed)
        print(f"error: {error}", file=sys.stderr)
        return 1
    if result.status == "interrupted":
        print(f"interrupted: continue with `python train.py {result.config.preset} --resume --logdir {result.logdir}`",
              file=sys.stderr)
        return INTERRUPTED
    return 0


if __name__ == "__main__":
    xla_flags.compilation_cache()  # a rerun or resume of the same setting loads its programs instead of compiling
    raise SystemExit(cli())
