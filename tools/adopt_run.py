"""Record a finished `train.py` run as the done part of a registered experiment run, so that GPU time is not
spent training the same config again.

    python -m tools.adopt_run reach-avoid-reward/semi-sparse --eval-json results/headline/ur5e_reach_avoid_ppo_eval.json \\
        --metrics results/runs/ur5e-reach-avoid-ppo/metrics.csv --no-timing

It writes `config.json`, `eval.json` and `metrics.csv` into the record folder of the run that trains the config
(`results/experiments/<experiment>/runs/<run>/seeds-0-<n-1>/`, the folder of the first registered run with the same
training config) and refuses, naming the difference, unless all of these hold: the training config of the
checkpoint that the `eval.py --json` file evaluated (it stores it) is the registered run's, its seeds included; the
evaluation covered every seed with the driver's settings (the run's own env config, `eval_envs` episodes,
`eval_seed`, `eval_last_steps`, the policy's mode), so it is the eval.json the driver would have written; the
metrics cover every seed up to the budget. The eval.json names its source. `--no-timing` blanks the
speed columns of the copied metrics (a run trained on several GPUs would otherwise pass for a one-GPU speed in the
tables and the planner's predictions).
"""

from __future__ import annotations

import argparse
import csv
import io
import json
import os
import warnings

from tools import experiment_state as ex

TIMING = ("steps_per_second", "wall_seconds")


def final_evaluation(evaluation_json: dict, budget: int, source: str) -> dict:
    """The file's one evaluation of a checkpoint at or past `budget` env steps; ValueError otherwise."""
    runs = [e for e in evaluation_json.get("evaluations", []) if e.get("policy", {}).get("env_steps", 0) >= budget]
    if len(runs) != 1 or "train_config" not in runs[0]["policy"]:
        raise ValueError(f"--eval-json {source!r} holds {len(runs)} evaluations of a checkpoint at or past {budget} env "
                         "steps: allowed is exactly one, of an eval.py --json that stores the checkpoint's config.")
    return runs[0]


def driver_eval(evaluation_json: dict, config, source: str) -> dict:
    """The driver's eval.json (`episode/<metric>` per seed, in seed order) from an eval.py JSON that evaluated the
    run's checkpoint as the driver does; ValueError naming what differs."""
    from agents.config import dataclass_from_dict

    e = final_evaluation(evaluation_json, config.num_timesteps, source)
    want = {"num_envs": config.eval_envs, "eval_seeds": [config.eval_seed], "last_steps": config.eval_last_steps,
            "actions": "deterministic", "env_name": config.env_name}
    got = {key: e.get(key) for key in want}
    got["env_config"] = dataclass_from_dict(type(config.env), e.get("env_config", {}))  # older files lack new fields
    want["env_config"] = config.env
    for key, value in want.items():
        if got[key] != value:
            raise ValueError(f"--eval-json {source!r}: {key}={got[key]!r} differs from the driver's {value!r}: allowed "
                             "is an evaluation made as the training driver makes it.")
    seeds = sorted(int(u["policy_seed"]) for u in e["units"])
    if seeds != list(range(config.seed, config.seed + config.seeds)):
        raise ValueError(f"--eval-json {source!r} evaluated seeds {seeds}: allowed is every seed of the run, "
                         f"{list(range(config.seed, config.seed + config.seeds))}.")
    units = sorted(e["units"], key=lambda u: int(u["policy_seed"]))
    return {"env_steps": int(e["policy"]["env_steps"]), "eval_envs": config.eval_envs,
            "device": evaluation_json.get("device", ""), **ex.driver_metrics(units),
            "source": {"eval_json": source, "command": evaluation_json.get("command", ""),
                       "code": evaluation_json.get("code", "")}}


def checked_metrics(text: str, config, source: str, timing: bool) -> str:
    """The metrics.csv text, its speed columns blanked unless `timing`; ValueError unless every seed was logged up
    to the budget."""
    rows = list(csv.DictReader(io.StringIO(text)))
    if not rows or "env_steps" not in rows[0] or "seed" not in rows[0]:
        raise ValueError(f"--metrics {source!r} has no env_steps and seed columns: allowed is a train.py metrics.csv.")
    last: dict[int, float] = {}
    for row in rows:
        seed = int(float(row["seed"]))
        last[seed] = max(last.get(seed, 0.0), float(row["env_steps"]))
    wanted = range(config.seed, config.seed + config.seeds)
    short = [s for s in wanted if last.get(s, 0.0) < config.num_timesteps]
    if short:
        raise ValueError(f"--metrics {source!r}: seed {short[0]} is logged to {last.get(short[0], 0):.0f} env steps: "
                         f"allowed are metrics of every seed up to the budget, {config.num_timesteps}.")
    if not timing:
        for row in rows:
            row.update({k: "" for k in TIMING if k in row})
    out = io.StringIO()
    writer = csv.DictWriter(out, fieldnames=list(rows[0]), lineterminator="\n")
    writer.writeheader()
    writer.writerows(rows)
    return out.getvalue()


def adopt(name: str, eval_json: str, metrics: str, timing: bool = True, out: str = ex.OUT_DIR) -> str:
    """Writes the part into the record and returns its folder (see the module docstring)."""
    from agents.checkpoint import write_atomic

    (experiment, runs), = ex.select([name])
    if len(runs) != 1 or "/" not in name:
        raise ValueError(f"{name!r} is invalid: allowed is one experiment/run.")
    run = runs[0]
    with open(eval_json) as f:
        evaluation_json = json.load(f)
    saved = final_evaluation(evaluation_json, run.budget(), eval_json)["policy"]["train_config"]
    seeds = int(saved.get("seeds", 0))
    owner = ex.storage(experiment, run)
    folder = os.path.join(ex.record_folder(out, *owner), f"seeds-0-{seeds - 1}")
    if os.path.exists(folder):
        raise ValueError(f"{folder} exists: allowed is a run with no part recorded for seeds 0-{seeds - 1}.")
    config = run.config(folder, first_seed=0, seeds=seeds)
    os.makedirs(folder)
    try:
        write_atomic(os.path.join(folder, "config.json"), json.dumps(saved, indent=2))
        with warnings.catch_warnings():  # a resume's notice of a changed num_timesteps: refused below instead
            warnings.simplefilter("ignore")
            reason = ex.config_difference(config, os.path.join(folder, "config.json"))
        if not reason and seeds != run.seeds:
            reason = f"seeds={seeds}, the run has {run.seeds}"
        if not reason and saved.get("num_timesteps") != run.budget():  # its schedules spanned another length
            reason = f"num_timesteps={saved.get('num_timesteps')}, the run has {run.budget()}"
        if reason:
            raise ValueError(f"--eval-json {eval_json!r} evaluated a run that is not {name}: {reason}.")
        evaluated = driver_eval(evaluation_json, config, eval_json)
        with open(metrics) as f:
            text = checked_metrics(f.read(), config, metrics, timing)
        write_atomic(os.path.join(folder, "eval.json"), json.dumps(evaluated, indent=2))
        write_atomic(os.path.join(folder, "metrics.csv"), text)
        state = ex.part_state(run, folder, 0, seeds)
        if state.status != "done":
            raise ValueError(f"{folder} reads as {state.status} for {name}, not done: {state.reason}")
    except BaseException:
        for file in os.listdir(folder):
            os.remove(os.path.join(folder, file))
        os.rmdir(folder)
        raise
    return folder


def main(argv: list[str] | None = None) -> str:
    p = argparse.ArgumentParser(prog="python -m tools.adopt_run", description=__doc__.splitlines()[0])
    p.add_argument("name", help="experiment/run to record the finished run as")
    p.add_argument("--eval-json", required=True, help="eval.py --json of the run's final checkpoint, every seed")
    p.add_argument("--metrics", required=True, help="the run's metrics.csv")
    p.add_argument("--no-timing", action="store_true", help="blank the speed columns (a run trained on several GPUs)")
    p.add_argument("--out", default=ex.OUT_DIR, help="the record's root (default results/experiments)")
    args = p.parse_args(argv)
    folder = adopt(args.name, args.eval_json, args.metrics, not args.no_timing, args.out)
    print(f"recorded {folder}")
    return folder


if __name__ == "__main__":
    from tools import run_cli

    run_cli(main)
