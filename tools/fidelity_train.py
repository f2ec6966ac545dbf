"""Trains a preset with fidelity variants applied to every UR5e env the run builds (training, evaluation):

    python -m tools.fidelity_train --variant wrist_3=0 -- ur5e-reach-ppo-paper --seed 0

The variants are `tools.fidelity.VARIANTS`, experimental hypotheses without an env field, so a learning run can test
what the learner-free tool measured (results/fidelity/README.md). The logdir's `variants.json` names them beside
the run's config.json, which cannot.
"""

from __future__ import annotations

import argparse
import json
import os
import sys

import envs
import train
from agents import provenance
from tools import run_cli
from tools.fidelity import VARIANTS, apply_variants


def split(argv: list[str]) -> tuple[list[str], list[str]]:
    """(this tool's arguments, train.py's) around the first "--"; ValueError without one."""
    if "--" not in argv:
        raise ValueError("train.py's arguments follow `--`: python -m tools.fidelity_train --variant V -- PRESET ...")
    at = argv.index("--")
    return argv[:at], argv[at + 1:]


def patch_env_builders(variants: list[str]) -> None:
    """Makes `envs.registry.build`, through which every env is built (by `envs.make`, `envs.from_config`, the
    driver and the evaluation), apply `variants` to each UR5e env."""
    build = envs.registry.build

    def varied(name, config):
        env = build(name, config)
        return apply_variants(env, variants) if env.robot.name == "ur5e" else env

    envs.registry.build = varied


def main(argv: list[str] | None = None):
    own, rest = split(sys.argv[1:] if argv is None else argv)
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--variant", nargs="+", required=True, metavar="NAME[=VALUE]", help=", ".join(VARIANTS))
    args = p.parse_args(own)
    config = train.parse(rest)
    if not config.env_name.startswith("ur5e"):
        raise ValueError(f"env {config.env_name!r} is not a UR5e env: the variants edit the UR5e.")
    apply_variants(envs.make(config.env_name), args.variant)  # refuses an unknown or malformed variant now
    patch_env_builders(args.variant)
    result = train.main(rest)
    with open(os.path.join(result.logdir, "variants.json"), "w") as f:
        json.dump({**provenance.stamp(), "variants": args.variant, "train_args": rest}, f, indent=2)
    print(f"trained with the variants {' '.join(args.variant)}")


if __name__ == "__main__":
    run_cli(main)
