"""The MPPI planner beside the shipped policies: how far the learners are from a planner that knows the dynamics.

    python -m tools.planner_table --out results/planner                  # every shipped task, the default budget
    python -m tools.planner_table --checkpoint results/checkpoints/ur5e-reach-ppo --budgets 16x8 64x16 --out DIR

For each shipped policy export (`--checkpoint`, default: every one under results/checkpoints) its task is its
trained env config; the planner (`agents.planner`, `--samples` x `--horizon`) and every export of that task are
evaluated on the same episodes (`--seeds` evaluation seeds x `--episodes` envs, the same eval seeds for all).
`--budgets KxH ...` evaluates the planner at each planning budget on the first task (`--budget-task` picks
another) for the success-against-budget plot. The planner's cost is reported as simulated env steps per executed
one (K x H x iterations) and as the warm wall clock per control step of the whole batch (the last seed's time,
after compilation, divided by the episode length).

`--from-json A/planner.json B/planner.json --out DIR` merges runs made separately (e.g. one per robot) into one
table, keeping each run's command, code version, device and date.

Writes to `--out`: `planner.json` (every row with its per-unit numbers, the options, command, code version,
device, date), `table.md` (per task: the planner against each export, and the gap between the planner and the
best export in reached percentage points) and, with `--budgets`, `budget.png`.
"""

from __future__ import annotations

import argparse
import dataclasses
import glob
import json
import os

import envs
from agents import evaluation, planner as planners, provenance
from agents.eval_stats import jsonable
from tools import run_cli

SHIPPED = os.path.join(os.path.dirname(os.path.dirname(os.path.abspath(__file__))), "results", "checkpoints")
COLUMNS = (("target_reached", "reached %", 100.0), ("self_collision", "self coll. %", 100.0),
           ("obstacle_collision", "obstacle coll. %", 100.0), ("distance", "distance (m)", 1.0))
"""The table's metrics: (summary key, header, scale)."""


def parse_budget(text: str) -> tuple[int, int]:
    """"64x16" -> (64, 16); ValueError naming the option otherwise."""
    try:
        samples, horizon = (int(part) for part in text.lower().split("x"))
    except ValueError:
        raise ValueError(f"--budgets entry {text!r} is invalid: allowed is SAMPLESxHORIZON, e.g. 64x16.") from None
    planners.PlannerConfig(samples=samples, horizon=horizon)  # range checks, naming the field
    return samples, horizon


def task_of(policy: evaluation.Policy, episode_length: int | None, backend: str | None):
    """(env name, env config) a policy is compared on: its trained env, optionally shortened or on another backend."""
    changes = {}
    if episode_length is not None:
        changes["episode_length"] = episode_length
    if backend is not None:
        changes["backend"] = backend
    return policy.train_env_name, envs.make_config(policy.train_env_name, policy.train_env_config, **changes)


def task_label(env_name: str, config) -> str:
    """"ur5e-reach-avoid" or "ur5e-reach-avoid, 3 moving obstacles": what tells two tasks apart in the table."""
    count = getattr(config, "num_obstacles", 1)
    motion = getattr(config, "obstacle_motion", "static")
    if count > 1 or motion != "static":
        return f"{env_name}, {count} {'' if motion == 'static' else motion + ' moving '}obstacles"
    return env_name


def row(result: evaluation.Result, episode_length: int) -> dict:
    """One table row: the policy, its summary and, for the planner, its cost."""
    policy = result.policy
    out = {"policy": policy.describe(), "summary": result.summary(), "units": result.units,
           "episodes": result.num_envs * len(result.units), "seed_seconds": result.seed_seconds}
    if policy.planner is not None:
        out["model_steps_per_step"] = policy.model_steps_per_step
        out["ms_per_control_step"] = 1000.0 * result.seed_seconds[-1] / episode_length
    return out


def group_tasks(checkpoints: list[str], episode_length: int | None, backend: str | None) -> list[dict]:
    """[{"task", "env_name", "env_config", "policies"}]: the exports grouped by task, in the order first seen; a
    task's env config (the planner's) is its first export's."""
    tasks: dict[str, dict] = {}
    for path in checkpoints:
        policy = evaluation.checkpoint_policy(path)
        env_name, env_config = task_of(policy, episode_length, backend)
        label = task_label(env_name, env_config)
        task = tasks.setdefault(label, {"task": label, "env_name": env_name, "env_config": env_config, "policies": []})
        task["policies"].append(policy)
    return list(tasks.values())


def evaluate_task(task: dict, config: planners.PlannerConfig, episodes: int, seeds: list[int], progress=print) -> dict:
    """{"task", "env_name", "env_config", "rows"}: the planner on the task's env config, then each export on its own
    trained one (the same episodes: the reset draws do not depend on the observation layout)."""
    rows = []
    for policy in [evaluation.planner_policy(config)] + task["policies"]:
        progress(f"{task['task']}: {policy.name}")
        env_name, env_config = task["env_name"], task["env_config"]
        if policy.export is not None:  # its own observation layout, the task's episode length and backend
            same = {k: getattr(env_config, k) for k in ("episode_length", "backend") if hasattr(env_config, k)}
            env_config = envs.make_config(env_name, policy.train_env_config, **same)
        result = evaluation.run(policy, env_name, env_config, episodes, seeds)
        rows.append(row(result, env_config.episode_length))
    return {"task": task["task"], "env_name": task["env_name"], "env_config": dataclasses.asdict(task["env_config"]),
            "rows": rows}


def sweep(task: dict, done: dict, config: planners.PlannerConfig, budgets, episodes: int, seeds: list[int],
          progress=print) -> list[dict]:
    """The planner's rows at each (samples, horizon) budget on `task` (`done`: its evaluated table entry, whose
    planner row is reused for the table's own budget)."""
    out = []
    for samples, horizon in budgets:
        if (samples, horizon) == (config.samples, config.horizon):
            out.append(done["rows"][0])
            continue
        progress(f"{task['task']}: budget {samples}x{horizon}")
        swept = dataclasses.replace(config, samples=samples, horizon=horizon)
        result = evaluation.run(evaluation.planner_policy(swept), task["env_name"], task["env_config"], episodes, seeds)
        out.append(row(result, task["env_config"].episode_length))
    return out


def gap(task: dict) -> float | None:
    """Reached percentage points of the planner minus the best export's (None without an export)."""
    reached = [r["summary"]["target_reached"]["mean"] for r in task["rows"]]
    return 100.0 * (reached[0] - max(reached[1:])) if len(reached) > 1 else None


def markdown(tasks: list[dict], budget_rows: list[dict], budget_task: str | None = None,
             budget_source: str | None = None) -> str:
    """The planner against each export per task, the gap per task, then the budget sweep (on `budget_task`; with
    `budget_source`, the sweep's own run, named because the table's rows of that task come from another one)."""
    head = "| task | policy | episodes | " + " | ".join(h for _, h, _ in COLUMNS) + " | model steps / step | ms / step |"
    lines = [head, "|" + "---|" * (head.count("|") - 1)]
    for task in tasks:
        for r in task["rows"]:
            policy = r["policy"]
            name = os.path.basename(policy["name"].rstrip("/")) if policy["kind"] == "checkpoint" else policy["name"]
            cells = [task["task"], name, str(r["episodes"])] + [_scaled(r["summary"], key, scale) for key, _, scale in COLUMNS]
            cost = [str(r.get("model_steps_per_step", "-")),
                    f"{r['ms_per_control_step']:.1f}" if "ms_per_control_step" in r else "-"]
            lines.append("| " + " | ".join(cells + cost) + " |")
    lines += ["", "| task | planner minus best export, reached (points) |", "|---|---:|"]
    for task in tasks:
        g = gap(task)
        lines.append(f"| {task['task']} | {'-' if g is None else f'{g:+.1f}'} |")
    if budget_rows:
        where = f"{budget_task}, {budget_source}" if budget_source else budget_task
        lines += ["", f"| planning budget on {where} (samples x horizon) | model steps / step | reached % | "
                      "self coll. % | obstacle coll. % | ms / step |", "|---|---:|---:|---:|---:|---:|"]
        for r in budget_rows:
            p = r["policy"]["planner"]
            rates = [_scaled(r["summary"], k, 100.0) for k in ("target_reached", "self_collision", "obstacle_collision")]
            lines.append(f"| {p['samples']} x {p['horizon']} | {r['model_steps_per_step']} | " + " | ".join(rates)
                         + f" | {r['ms_per_control_step']:.1f} |")
    return "\n".join(lines) + "\n"


def _scaled(summary: dict, key: str, scale: float) -> str:
    """"mean ± sample std over units" in the column's unit, "-" if the env has no such metric."""
    s = summary.get(key)
    if s is None:
        return "-"
    digits = 1 if scale > 1 else 3
    std = s.get("std_units")
    text = f"{scale * s['mean']:.{digits}f}"
    return text + (f" ± {scale * std:.{digits}f}" if std is not None and s.get("units", 1) > 1 else "")


BUDGET_METRICS = (("target_reached", "reached"), ("obstacle_collision", "obstacle collision"),
                  ("self_collision", "self collision"))
"""The metrics `plot_budget` draws (summary key, label), in this order and colour cycle."""


def best_export_reference(task: dict | None) -> list[tuple[str, float, str]]:
    """`plot_budget`'s reference for a planner sweep: the reached percentage of the best export of `task` (the
    sweep's entry of that task, if evaluated: `swept_task`), drawn in grey; none without one."""
    exports = [r for r in (task or {}).get("rows", []) if r["policy"]["kind"] == "checkpoint"]
    if not exports:
        return []
    best = max(exports, key=lambda r: r["summary"]["target_reached"]["mean"])
    return [("", 100.0 * best["summary"]["target_reached"]["mean"],
             f"{os.path.basename(best['policy']['name'].rstrip('/'))}: reached")]


def plot_budget(budget_rows: list[dict], title: str, path: str, references: list[tuple[str, float, str]],
                who: str = "planner", method: str = "MPPI", split: bool = False) -> None:
    """Reached and collision percentages against the planning budget (simulated steps per step, log scale), with
    dashed `references` `(metric, percent, label)` in their metric's colour (grey for another key). `who` names the
    lines and `method` the title (the shield's sweep: `tools.shield_budget`); `split`: reach and collisions in two
    panels, each scaled to its own values, instead of one from 0 to 100 %."""
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    cost = [r["model_steps_per_step"] for r in budget_rows]
    fig, axes = plt.subplots(2 if split else 1, 1, figsize=(6, 5.0 if split else 3.6), sharex=True, squeeze=False)
    panel = {key: axes[int(split and key != "target_reached"), 0] for key, _ in BUDGET_METRICS}
    colours = {}
    for n, (key, what) in enumerate(BUDGET_METRICS):
        if key in budget_rows[0]["summary"]:
            colours[key] = f"C{n}"
            panel[key].plot(cost, [100.0 * r["summary"][key]["mean"] for r in budget_rows], "o-", color=colours[key],
                            label=f"{who}: {what}")
    for key, percent, label in references:
        panel.get(key, axes[0, 0]).axhline(percent, color=colours.get(key, "gray"), ls="--", label=label)
    ax = axes[-1, 0]
    ax.set_xscale("log")
    ax.minorticks_off()
    ax.set_xticks(cost, [f"{r['policy']['planner']['samples']}x{r['policy']['planner']['horizon']}\n{c}"
                         for r, c in zip(budget_rows, cost)], fontsize=7)
    ax.set_xlabel("planning budget: samples x horizon (simulated env steps per env step)", fontsize=8)
    for a in axes[:, 0]:
        a.set_ylabel("% of episodes")
        a.legend(fontsize=7, loc="lower right" if not split else "best",
                 bbox_to_anchor=None if split else (1.0, 0.12))
    if split:
        axes[1, 0].set_ylim(bottom=0)
    else:
        ax.set_ylim(0, 100)
    axes[0, 0].set_title(f"{method} on {title}", fontsize=9)
    fig.tight_layout()
    fig.savefig(path, dpi=120)
    plt.close(fig)


def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(prog="python -m tools.planner_table", description=__doc__.split("\n\n")[0])
    p.add_argument("--checkpoint", nargs="+", default=None, metavar="PATH",
                   help="policy exports to compare with (default: every one under results/checkpoints)")
    p.add_argument("--out", required=True, metavar="DIR")
    p.add_argument("--from-json", nargs="+", default=None, metavar="FILE",
                   help="merge the planner.json files of earlier runs into one table instead of evaluating")
    p.add_argument("--episodes", type=int, default=256, help="envs per evaluation seed")
    p.add_argument("--seeds", type=int, default=2, help="evaluation seeds (the last one's time is the warm timing)")
    p.add_argument("--samples", type=int, default=planners.PlannerConfig.samples)
    p.add_argument("--horizon", type=int, default=planners.PlannerConfig.horizon)
    p.add_argument("--iterations", type=int, default=planners.PlannerConfig.iterations)
    p.add_argument("--temperature", type=float, default=planners.PlannerConfig.temperature)
    p.add_argument("--noise", type=float, default=planners.PlannerConfig.noise)
    p.add_argument("--budgets", nargs="*", default=[], metavar="KxH", help="planning budgets for the sweep")
    p.add_argument("--budget-task", type=int, default=0, help="index of the task (in table order) the sweep runs on")
    p.add_argument("--episode-length", type=int, default=None, help="shorten episodes (default: as trained)")
    p.add_argument("--backend", default=None, help="physics backend (default: as the env config says)")
    args = p.parse_args(argv)
    if args.from_json:
        merged = merge(args.from_json, args.out)
        print(markdown(merged["tasks"], merged["budgets"], merged["budget_task"], merged.get("budget_source")))
        return 0
    for name in ("episodes", "seeds"):
        if getattr(args, name) < 1:
            raise ValueError(f"--{name}={getattr(args, name)} is invalid: allowed is an integer >= 1.")
    config = planners.PlannerConfig(samples=args.samples, horizon=args.horizon, iterations=args.iterations,
                                    temperature=args.temperature, noise=args.noise)
    budgets = [parse_budget(b) for b in args.budgets]
    checkpoints = args.checkpoint or sorted(os.path.dirname(p) for p in glob.glob(os.path.join(SHIPPED, "*", "policy.json")))
    if not checkpoints:
        raise ValueError(f"--checkpoint is empty and {SHIPPED} holds no policy export: allowed are export directories.")
    seeds = [evaluation.DEFAULT_EVAL_SEED + i for i in range(args.seeds)]
    groups = group_tasks(checkpoints, args.episode_length, args.backend)
    if budgets and not 0 <= args.budget_task < len(groups):
        raise ValueError(f"--budget-task={args.budget_task} is invalid: allowed is 0..{len(groups) - 1}.")
    report = {**provenance.stamp(), "planner": dataclasses.asdict(config), "episodes": args.episodes,
              "eval_seeds": seeds, "tasks": [], "budget_task": groups[args.budget_task]["task"] if budgets else None,
              "budgets": []}
    os.makedirs(args.out, exist_ok=True)
    for group in groups:  # written after every task: a run cut short keeps what it finished
        report["tasks"].append(evaluate_task(group, config, args.episodes, seeds))
        write(args.out, report)
    if budgets:
        group = groups[args.budget_task]
        report["budgets"] = sweep(group, report["tasks"][args.budget_task], config, budgets, args.episodes, seeds)
        write(args.out, report)
    print(markdown(report["tasks"], report["budgets"], report["budget_task"]))
    return 0


def write(out: str, report: dict) -> None:
    """planner.json, table.md and (with a sweep) budget.png of `report`."""
    with open(os.path.join(out, "planner.json"), "w") as f:
        json.dump(jsonable(report), f, indent=2, default=str)
    with open(os.path.join(out, "table.md"), "w") as f:
        f.write(markdown(report["tasks"], report["budgets"], report["budget_task"], report.get("budget_source")))
    if report["budgets"]:
        task = swept_task(report)
        title = report["budget_task"] + (f"\n{report['budget_source']}" if report.get("budget_source") else "")
        plot_budget(report["budgets"], title, os.path.join(out, "budget.png"), best_export_reference(task))


def swept_task(report: dict) -> dict | None:
    """The entry of the task a report's sweep ran on: its `budget_reference` where a merge kept one, else the
    report's own entry of that task (None if the report did not evaluate it)."""
    return report.get("budget_reference") or next((t for t in report["tasks"] if t["task"] == report["budget_task"]),
                                                  None)


def merge(paths: list[str], out: str) -> dict:
    """One report of several planner.json files (their tasks in order; a task in several files keeps the first
    file's rows, so a sweep made apart with fewer episodes adds only its sweep), each source's command, code,
    device and date kept under "sources"; at the top, the merge's command and the sources' codes, devices, dates.
    When the table's rows of the swept task come from another file than the sweep, the sweep keeps its own file's
    rows of that task as its reference (`budget_reference`) and names its run (`budget_source`): the two may be
    runs of different code."""
    reports = [json.load(open(path)) for path in paths]
    swept = [r for r in reports if r.get("budgets")]
    if len(swept) > 1:
        raise ValueError(f"--from-json holds {len(swept)} budget sweeps: allowed is at most one.")
    first: dict[str, dict] = {}
    for r in reports:
        for t in r["tasks"]:
            first.setdefault(t["task"], t)
    joined = lambda key: ", ".join(dict.fromkeys(str(r[key]) for r in reports))
    merged = {"command": provenance.command(), "code": joined("code"), "device": joined("device"),
              "date": joined("date"), "sources": [{k: r[k] for k in ("command", "code", "device", "date", "planner", "episodes", "eval_seeds")}
                          | {"tasks": [t["task"] for t in r["tasks"]], "path": path} for path, r in zip(paths, reports)],
              "tasks": list(first.values()),
              "budget_task": swept[0]["budget_task"] if swept else None,
              "budgets": swept[0]["budgets"] if swept else []}
    if swept:
        own = swept_task(swept[0])
        if own is not None and first.get(own["task"]) is not own:
            merged["budget_reference"] = own
            merged["budget_source"] = (swept[0].get("budget_source")
                                       or f"the sweep's own run (code {swept[0]['code']}, {swept[0]['date']})")
    os.makedirs(out, exist_ok=True)
    write(out, merged)
    return merged

if __name__ == "__main__":
    run_cli(main)
