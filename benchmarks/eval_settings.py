"""Evaluation across env settings: the wall clock of each further setting of a sweep in one process.

    python -m benchmarks.eval_settings results/checkpoints/panda-reach-avoid-ppo --field obstacle_radius \
        --values 0.025 0.05 0.1 0.2 0.3 --out results/time_to_result/eval_settings

A cross-evaluation table (a policy trained on one setting evaluated on others, e.g. the paper's obstacle-size table)
evaluates one checkpoint on many env configs in one process. This times each of them through `agents.sweep.run`: the
first setting pays for loading the checkpoint and compiling; a further one of a field in the env config's
`TRACED_FIELDS` runs the program compiled before with the new value as its argument (or, where the value changes an
array shape, compiles one more), any other field builds and compiles its own program (or loads it from the persistent
compilation cache), as `evaluation.run` does. Per setting: the wall clock, the evaluation's own clock and the
success, in the order evaluated; the header says whether the field was a program argument.

Writes `--out`.json (every setting, command, code version, device, date) and `--out`.md (the table).
"""

from __future__ import annotations

import argparse
import json
import time

import jax

import envs
from agents import evaluation, provenance, sweep
from agents.eval_stats import jsonable
from tools import literal_or_text, run_cli

SUCCESS = "target_reached"


def settings(env_name: str, base, field: str, values: list[str]) -> list:
    """`base` with `field` set to each value, every one validated before anything is evaluated (a ValueError names
    the field, the value and what is allowed)."""
    return [envs.registry.make_config(env_name, base, **{field: literal_or_text(text)}) for text in values]


def evaluate(checkpoint: str, field: str, values: list[str], num_envs: int, seeds: int, log=print) -> tuple[list, bool]:
    """One row per value, evaluated in this order in this process (the first includes loading the checkpoint), and
    whether `field` was an argument of the evaluation program (`agents.sweep.traced`)."""
    rows = []
    start = time.perf_counter()
    policy = evaluation.checkpoint_policy(checkpoint)
    env_name = policy.train_env_name
    configs = settings(env_name, policy.train_env_config, field, values)
    eval_seeds = [evaluation.DEFAULT_EVAL_SEED + k for k in range(seeds)]
    for i, (text, config) in enumerate(zip(values, configs)):
        t0 = time.perf_counter()
        result, = sweep.run(policy, env_name, field, [config], num_envs, eval_seeds=eval_seeds)
        wall = time.perf_counter() - (start if i == 0 else t0)
        success = float(sum(u["metrics"][SUCCESS] for u in result.units) / len(result.units))
        rows.append({"value": text, "wall_seconds": round(wall, 2), "evaluation_seconds": round(result.seconds, 2),
                     "success": success, "units": len(result.units)})
        log(f"{field}={text}: {wall:.1f} s wall ({result.seconds:.1f} s evaluating), success {100 * success:.1f} %")
    return rows, sweep.traced(configs[0], field)


def markdown(meta: dict, rows: list[dict]) -> str:
    """The table of `sweep`'s rows under a header naming the command, code, device and date."""
    lines = [f"# Evaluation across env settings: {meta['checkpoint']} ({meta['device']}, {meta['date']})", "",
             f"Command: `{meta['command']}`, code {meta['code']}, jax {meta['jax']}; {meta['num_envs']:,} episodes x "
             f"{meta['seeds']} eval seed(s) x {rows[0]['units'] // meta['seeds']} trained seed(s) per setting, in this "
             f"order in one process (the first row includes loading the checkpoint); {meta['field']} "
             + ("is an argument of the evaluation program." if meta["traced"] else "compiles a program per value."), "",
             f"| {meta['field']} | wall clock (s) | evaluating (s) | target reached |", "|---|---:|---:|---:|"]
    lines += [f"| {r['value']} | {r['wall_seconds']:.1f} | {r['evaluation_seconds']:.1f} | {100 * r['success']:.1f} % |"
              for r in rows]
    return "\n".join(lines) + "\n"


def main(argv=None) -> None:
    """Parses the command line, runs the sweep, prints the table and writes --out's files."""
    parser = argparse.ArgumentParser(prog="python -m benchmarks.eval_settings", description=__doc__.split("\n\n")[0])
    parser.add_argument("checkpoint", help="a train.py logdir, checkpoint step directory or policy export")
    parser.add_argument("--field", required=True, help="the env config field swept, e.g. obstacle_radius")
    parser.add_argument("--values", nargs="+", required=True, help="its values, evaluated in this order")
    parser.add_argument("--num-envs", type=int, default=4096, help="episodes per eval seed and trained seed")
    parser.add_argument("--seeds", type=int, default=1, help="evaluation seeds per setting")
    parser.add_argument("--out", help="write OUT.json and OUT.md")
    args = parser.parse_args(argv)
    if args.num_envs < 1 or args.seeds < 1:
        parser.error(f"--num-envs={args.num_envs} / --seeds={args.seeds} are invalid: allowed are integers >= 1")
    rows, traced = evaluate(args.checkpoint, args.field, args.values, args.num_envs, args.seeds)
    meta = {**provenance.stamp(), "jax": jax.__version__, "checkpoint": args.checkpoint, "field": args.field,
            "num_envs": args.num_envs, "seeds": args.seeds, "traced": traced}
    text = markdown(meta, rows)
    print(text)
    if args.out:
        with open(args.out + ".json", "w") as f:
            json.dump(jsonable({**meta, "settings": rows}), f, indent=1)
        with open(args.out + ".md", "w") as f:
            f.write(text)


if __name__ == "__main__":
    run_cli(main)
