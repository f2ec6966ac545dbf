"""Copy a trained policy into `results/checkpoints/`: its policy export (`agents.export`), keeping only
the chosen trained seeds, so the repository carries a few hundred kB per row instead of a checkpoint.

    python -m tools.ship_checkpoint .ckpt/panda-reach-ppo results/checkpoints/panda-reach-ppo \\
        --best-from results/headline/panda_reach_ppo_eval.json     # the seed with the highest target-reached rate
    python -m tools.ship_checkpoint RUN DST --seeds 0 3                 # or name the seeds

SRC is a train.py logdir (its newest checkpoint), a checkpoint step directory or an export; a
checkpoint without an export gets one written first. `--best-from` reads an `eval.py --json` file
of that same checkpoint (or the run's own eval.json, which the training driver writes of its final
checkpoint) and keeps the seed with the highest target-reached rate (ties: fewer collisions).
"""

from __future__ import annotations

import argparse
import json
import os

from agents import evaluation, export
from tools import run_cli


def _score(metrics: dict) -> tuple[float, float]:
    """Target reached first, then fewer self + obstacle collisions."""
    return metrics["target_reached"], -(metrics.get("self_collision", 0.0) + metrics.get("obstacle_collision", 0.0))


def _best_of_run_eval(eval_json: str, data: dict, env_steps: int, seeds: list[int] | None) -> int:
    """`best_seed` from a run's own eval.json: its per-seed lists, in the order of the export's `seeds`."""
    bad = f"--best-from {eval_json!r} is invalid:"
    if data.get("env_steps") != env_steps:
        raise ValueError(f"{bad} it evaluates {data.get('env_steps')} env steps, the checkpoint has {env_steps}; "
                         "allowed is the eval.json of that checkpoint's run.")
    if not seeds:
        raise ValueError(f"{bad} a run's eval.json names no seeds; allowed with the export's seeds only.")
    per_seed = {name: data["per_seed"].get(f"episode/{name}")
                for name in ("target_reached", "self_collision", "obstacle_collision")}
    lengths = {k: len(v) for k, v in per_seed.items() if v is not None}
    if "target_reached" not in lengths or set(lengths.values()) != {len(seeds)}:
        raise ValueError(f"{bad} its per-seed lists {lengths} do not hold one value for each of the export's seeds "
                         f"{seeds}; allowed is the eval.json of the run the export was taken from.")
    units = [{k: v[i] for k, v in per_seed.items() if v is not None} for i in range(len(seeds))]
    return seeds[max(range(len(seeds)), key=lambda i: _score(units[i]))]


def best_seed(eval_json: str, env_steps: int, seeds: list[int] | None = None) -> int:
    """The trained seed with the highest target-reached rate in an eval.py JSON of the checkpoint
    that has `env_steps` (ties: the lower self + obstacle collision rate), or in a run's own eval.json
    (the training driver's, per seed in the order of the export's `seeds`)."""
    with open(eval_json) as f:
        data = json.load(f)
    if "per_seed" in data:
        return _best_of_run_eval(eval_json, data, env_steps, seeds)
    runs = [e for e in data.get("evaluations", []) if e.get("policy", {}).get("env_steps") == env_steps]
    if not runs:
        found = sorted({e.get("policy", {}).get("env_steps") for e in data.get("evaluations", [])}, key=str)
        raise ValueError(f"--best-from {eval_json!r} is invalid: it holds no evaluation of the checkpoint at "
                         f"{env_steps} env steps (it has {found}); allowed is an eval.py --json of that checkpoint.")
    scores = {}
    for unit in runs[0]["units"]:
        score = _score(unit["metrics"])
        seed = int(unit["policy_seed"])
        scores[seed] = max(score, scores.get(seed, score))
    return max(scores, key=lambda s: scores[s])


def ship(src: str, dst: str, seeds: list[int] | None = None, best_from: str | None = None) -> str:
    policy = evaluation.checkpoint_policy(src)  # writes a missing export
    if best_from:
        if seeds:
            raise ValueError("--seeds and --best-from are exclusive: allowed is one of them.")
        seeds = [best_seed(best_from, policy.export.env_steps, policy.export.seeds)]
    return export.select(policy.export.path, dst, seeds)


def main(argv: list[str] | None = None) -> str:
    p = argparse.ArgumentParser(prog="python -m tools.ship_checkpoint", description=__doc__.splitlines()[0])
    p.add_argument("src", help="train.py logdir (newest checkpoint), checkpoint step directory or policy export")
    p.add_argument("dst", help="directory to write the export to (e.g. results/checkpoints/<preset>)")
    p.add_argument("--seeds", type=int, nargs="+", help="trained seeds to keep (default: all)")
    p.add_argument("--best-from", metavar="EVAL_JSON", help="keep the best seed of this eval.py --json file, or of "
                   "the run's own eval.json (the training driver's, same checkpoint)")
    args = p.parse_args(argv)
    out = ship(args.src, args.dst, args.seeds, args.best_from)
    with open(os.path.join(out, "policy.json")) as f:
        print(f"wrote {out}: seeds {json.load(f)['seeds']}")
    return out


if __name__ == "__main__":
    run_cli(main)
