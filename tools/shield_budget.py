"""A shielded agent's reach and collisions against the shield's planning budget, beside the agent unshielded.

    python -m tools.shield_budget results/obstacles/shield/RUN_shield_*_h200.json \\
        --unshielded results/experiments/EXP/runs/RUN/seeds-0-0/eval.json --out results/obstacles/shield/RUN_budget.png

Each JSON is eval.py's report of one `--checkpoint PATH --shield` evaluation (`agents/shield.py`) at one budget
(`--planner.samples` x `--planner.horizon`); all must evaluate the same policy on the same episodes. `--unshielded`
is the same policy's evaluation on those episodes without the shield: eval.py's JSON or a training run's eval.json
(the driver's eval seed). The figure is `tools.planner_table.plot_budget`'s, with the unshielded agent's reach and
obstacle collisions as dashed lines.
"""

from __future__ import annotations

import argparse
import json

from tools.planner_table import plot_budget

SAME = ("env_name", "env_config", "num_envs", "eval_seeds")
"""What every evaluation of one sweep shares (with the policy's name): the same episodes."""
REFERENCES = (("target_reached", "reached"), ("obstacle_collision", "obstacle collision"))
"""The unshielded agent's metrics drawn as dashed lines: (summary key, label)."""


def _evaluation(path: str) -> dict:
    """The one evaluation of eval.py's JSON report at `path`."""
    with open(path) as f:
        evaluations = json.load(f)["evaluations"]
    if len(evaluations) != 1:
        raise ValueError(f"{path!r} holds {len(evaluations)} evaluations: allowed is one (one policy, one budget).")
    return evaluations[0]


def budget_rows(paths: list[str]) -> list[dict]:
    """The shielded evaluations of `paths` ordered by their cost (model steps per executed step, also set at the top
    level as the planner's rows have it); ValueError where one is not shielded or they differ in policy or episodes."""
    rows = [_evaluation(path) for path in paths]
    for path, row in zip(paths, rows):
        if row["policy"]["kind"] != "shielded":
            raise ValueError(f"{path!r} evaluates a {row['policy']['kind']} policy: allowed are shielded evaluations "
                             "(eval.py --checkpoint PATH --shield).")
        differs = [key for key in SAME if row[key] != rows[0][key]]
        differs += ["policy"] if row["policy"]["name"] != rows[0]["policy"]["name"] else []
        if differs:
            raise ValueError(f"{path!r} differs from {paths[0]!r} in {', '.join(differs)}: allowed are evaluations "
                             "of one policy on the same episodes.")
    rows = [{**row, "model_steps_per_step": row["policy"]["model_steps_per_step"]} for row in rows]
    return sorted(rows, key=lambda row: row["model_steps_per_step"])


def unshielded_percents(path: str, num_envs: int) -> dict:
    """`{metric: percent}` of `REFERENCES` from eval.py's JSON (its one evaluation) or a training run's eval.json;
    ValueError unless it evaluated `num_envs` episodes (a seed), as the shielded evaluations did."""
    with open(path) as f:
        report = json.load(f)
    if "evaluations" in report:
        evaluation = _evaluation(path)
        episodes = evaluation["num_envs"]
        percents = {key: 100.0 * evaluation["summary"][key]["mean"] for key, _ in REFERENCES}
    else:
        episodes = report["eval_envs"]
        percents = {key: 100.0 * report["mean"][f"episode/{key}"] for key, _ in REFERENCES}
    if episodes != num_envs:
        raise ValueError(f"--unshielded {path!r} evaluated {episodes} episodes: allowed is the shielded evaluations' "
                         f"{num_envs}, on the same episodes.")
    return percents


def main(argv: list[str] | None = None) -> None:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("shielded", nargs="+", help="eval.py JSON reports of --shield evaluations, one budget each")
    p.add_argument("--unshielded", required=True, help="the policy's evaluation on the same episodes without it")
    p.add_argument("--out", required=True, help="the figure to write (.png)")
    p.add_argument("--label", help="the policy's name in the title (default: its path in the reports)")
    args = p.parse_args(argv)
    rows = budget_rows(args.shielded)
    first = rows[0]
    percents = unshielded_percents(args.unshielded, first["num_envs"])
    references = [(key, percents[key], f"unshielded: {label}") for key, label in REFERENCES]
    title = f"{first['env_name']}, {args.label or first['policy']['name']}\n{first['num_envs']} episodes a budget"
    plot_budget(rows, title, args.out, references, who="shielded", method="the shield", split=True)
    print(f"wrote {args.out}")


if __name__ == "__main__":
    main()
