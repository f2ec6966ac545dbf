"""Writes the results tables from the committed JSON files under results/.

    python -m tools.results_index            # rewrite every generated table in place
    python -m tools.results_index --check    # exit 1 if a committed table differs from what this would write

A markdown file holds a generated table between `<!-- table:NAME -->` and `<!-- /table -->`; this tool
rewrites what lies between them from `TABLES[NAME]` and leaves the rest of the file alone. The files it
reads are README.md, results/README.md and results/<study>/README.md. Our numbers come only from the JSON
files that eval.py, tools/paper_tables.py and the benchmarks wrote; the paper's numbers come from
assets/paper_numbers.json, each entry citing the paper's table or section.

Which results file makes which row is not listed here but in results/index.json, the results' own index: for
each table its rows, each with its label, its file (relative to results/) and the table's other fields (the
paper's row beside it, the experiment and run a row is read from, a figure's command), and for a table of
eval.py runs its columns (keys of COLUMNS). This module holds the tables (those built from the index's rows and those
computed from one JSON file: baselines, workspaces, throughput, ...) and the command line; their building blocks (the
paper's numbers, the reader of results/, the cells) are in tools/results_cells.py. To add a
row: write its JSON under results/<study>/, add the row to its table in results/index.json, and run
`python -m tools.results_index`; tests/test_results_index.py checks that every file the index names exists.
"""

from __future__ import annotations

import argparse
import glob
import json
import os
import re
import sys
from typing import Callable

from tools import experiment_registry  # noqa: F401  (registers the experiments in EXPERIMENTS)
from tools.experiment_spec import EXPERIMENTS
from tools.paper_tables import WORKSPACE_NAMES
from tools.results_cells import (PAPER_BASELINES, PAPER_OBSTACLE, PAPER_ROWS, PAPER_THROUGHPUT,
                                 PAPER_WORKSPACE, ROOT, Context, seed_stats, train_config, collisions,
                                 listed_table, markdown, millions, paper_action_space, paper_collisions, paper_pct,
                                 pct, rate, runs, thousands, time_to_result_cell, eval_settings_cell,
                                 eval_wall_cell, per_gpu_count)

# ------------------------------------------------------------------------------------------------
# The studies: the rows of the tables below are listed in results/index.json.

def sampled_table(ctx: Context) -> list[list[str]]:
    rows = [["policy", "deterministic: reached", "sampled: reached", "deterministic: collisions", "sampled: collisions",
             "files"], ["---", "---:", "---:", "---:", "---:", "---"]]
    for row in ctx.index["sampled_actions"]["rows"]:  # a deterministic evaluation, the same policy with sampled actions
        label, det, sto = row["label"], row["file"], row["sampled_file"]
        d, s = ctx.evaluation(det), ctx.evaluation(sto)
        rows.append([label, pct(d["summary"]["target_reached"]), pct(s["summary"]["target_reached"]), collisions(d),
                     collisions(s), f"{ctx.link(det)}, {ctx.link(sto)}"])
    return rows


def finished_experiment_row(ctx: Context, experiment: str, run: str) -> dict | None:
    """The table.json row of `experiment`/`run` if all its seeds are evaluated, else None."""
    file = f"experiments/{experiment}/table.json"
    if not os.path.exists(os.path.join(ctx.results, file)):
        return None
    for row in ctx.json(file)["rows"]:
        if row["run"] == run and "cross" not in row and row.get("seeds_evaluated") == row["seeds"]:
            return row
    return None


def _seed_rate(values: list[float]) -> str:
    """Mean ± sample std over seeds and the mean's 95 % confidence interval, in %; one seed: its value."""
    return seed_stats(values, 1, 100.0, " %")


def paper_settings_seeds(ctx: Context, runs_dir: str) -> list[dict]:
    """Each seed's evaluation means ({"episode/<metric>": value}) of the train.py eval.json files under
    `runs_dir`/seed*/ (the `*-paper` presets; a folder holds one seed or, from `--seeds N`, several), in folder
    and then seed order."""
    seeds = []
    for path in sorted(glob.glob(os.path.join(ctx.results, runs_dir, "seed*", "eval.json"))):
        per_seed = ctx.json(os.path.relpath(path, ctx.results))["per_seed"]
        count = len(per_seed["episode/target_reached"])
        seeds += [{key: values[i] for key, values in per_seed.items()} for i in range(count)]
    return seeds


def _paper_settings_cell(ctx: Context, runs_dir: str, paper_key: str) -> str:
    """The paper-settings column: mean ± sample std over `paper_settings_seeds`, collisions as the paper's row
    counts them."""
    files = sorted(glob.glob(os.path.join(ctx.results, runs_dir, "seed*", "eval.json")))
    seeds = paper_settings_seeds(ctx, runs_dir)
    get = lambda key: [s[f"episode/{key}"] for s in seeds]
    cell = f"{_seed_rate(get('target_reached'))} / {_seed_rate(get('self_collision'))} self"
    if "obstacle_collision" in PAPER_ROWS[paper_key]:
        cell += f", {_seed_rate(get('obstacle_collision'))} obstacle"
    steps = ctx.json(os.path.relpath(files[0], ctx.results))["env_steps"]
    return f"{cell} at {len(seeds)} seed{'s' * (len(seeds) > 1)} x {millions(steps)} steps"


def _experiment_cell(row: dict, paper_key: str) -> str:
    """'96.5 ± 0.3 % / 0.6 ± 0.1 % self at 5 seeds x 100.0M steps' from a table.json row (collisions as the
    paper's row counts them)."""
    seeds = row["per_seed"]
    ours = [_seed_rate(seeds["target_reached"]), _seed_rate(seeds["self_collision"]) + " self"]
    if "obstacle_collision" in PAPER_ROWS[paper_key]:  # the paper's row counts obstacle collisions
        ours[1] += ", " + _seed_rate(seeds["obstacle_collision"]) + " obstacle"
    return f"{ours[0]} / {ours[1]} at {row['seeds_evaluated']} seeds x {millions(row['env_steps'])} steps"


def _training_row(algo: str, report: dict) -> list[str]:
    """The README's row of a `benchmarks/train_throughput.py` report: the training rate per GPU count."""
    one = next(r for r in report["rows"] if r["setting"] == "1dev")
    return [f"UR5e reach {algo} training env steps/s, 1 seed, {one['num_envs']:,} envs per GPU ({report['meta']['date']})",
            "", "", per_gpu_count(report["rows"])]


def readme_table(ctx: Context) -> list[list[str]]:
    """README.md's short table: the headline rows, the pseudo-IK baseline and the speeds. A headline row that
    results/index.json's `readme.from_experiments` names shows its registered experiment's run of the same config
    trained further, once every seed of that run is evaluated; the rows of `readme.experiment_rows` follow the
    headline rows, each once every seed of its run is evaluated."""
    readme = ctx.index["readme"]
    from_experiments = {r["file"]: (r["label"], r["experiment"], r["run"]) for r in readme["from_experiments"]}
    paper_settings = readme["paper_settings"]
    rows = [["", "paper (RTX 3090 Ti)", "ours, the paper's settings", "ours, the row's preset"], ["---", "---:", "---:", "---:"]]
    for run in runs(ctx, "headline"):
        paper = " / ".join([paper_pct(PAPER_ROWS[run.paper]["target_reached"]), paper_collisions(run.paper)])
        settings = _paper_settings_cell(ctx, paper_settings[run.file], run.paper) if run.file in paper_settings else ""
        label, experiment, name = from_experiments.get(run.file, (run.label, "", ""))
        row = finished_experiment_row(ctx, experiment, name) if experiment else None
        if row is not None:
            rows.append([label + ": reached / collisions", paper, settings, _experiment_cell(row, run.paper)])
            continue
        ev = ctx.evaluation(run.file)
        rows.append([run.label + ": reached / collisions", paper, settings,
                     f"{pct(ev['summary']['target_reached'])} / {collisions(ev)} at "
                     f"{ev['summary']['target_reached']['units']} seeds x {millions(ev['policy']['env_steps'])} steps"])
    for listed in readme["experiment_rows"]:
        label, paper_key = listed["label"], listed["paper"]
        row = finished_experiment_row(ctx, listed["experiment"], listed["run"])
        if row is None:
            continue
        rows.append([label + ": reached / collisions",
                     " / ".join([paper_pct(PAPER_ROWS[paper_key]["target_reached"]), paper_collisions(paper_key)]),
                     "", _experiment_cell(row, paper_key)])
    b = _baseline_rows(ctx)
    ik = [b[("ur5e", "pseudo_ik", "absolute", r)]["summary"]["target_reached"] for r in (0.01, 0.02)]
    rows.append(["baseline: pseudo-IK, UR5e, absolute control: reached, 1 cm / 2 cm",
                 " / ".join(paper_pct(PAPER_BASELINES[("pseudo_ik", r)]["target_reached"]) for r in (0.01, 0.02)),
                 "", " / ".join(pct(s) for s in ik)])
    env = {r["env"]: r for r in ctx.json("throughput/env_throughput.json")["rows"] if r["num_envs"] == 8192}
    meta = ctx.json("throughput/env_throughput.json")["meta"]
    rows.append([f"UR5e reach / reach-avoid env steps/s, 8,192 envs (env only, {meta['date']})",
                 f"{thousands(PAPER_THROUGHPUT['ur5e-reach'])} / {thousands(PAPER_THROUGHPUT['ur5e-reach-avoid'])}",
                 "", f"{thousands(env['ur5e-reach']['steps_per_s'])} / {thousands(env['ur5e-reach-avoid']['steps_per_s'])}"])
    rows.append(_training_row("PPO", ctx.json(readme["ppo_throughput_file"])))  # on `ur5e-reach-ppo`
    rows.append(_training_row("fast SAC", ctx.json(readme["sac_fast_throughput_file"])))  # on the fast SAC preset
    rows.append(_time_to_result_row(ctx, readme))
    wall, sweep = ctx.json(readme["eval_wall_clock_file"]), ctx.json(readme["eval_settings_file"])
    rows.append([f"eval.py on a shipped checkpoint (`ur5e-reach-ppo`, 5 seeds x 4,096 episodes), wall clock of the process ({wall['date']})",
                 "", "", eval_wall_cell(wall)])
    rows.append([f"A further env setting in one process (`benchmarks/eval_settings`, Panda reach-avoid policy, "
                 f"{sweep['num_envs']:,} episodes; {sweep['date']})", "", "", eval_settings_cell(sweep)])
    return rows


def _time_to_result_row(ctx: Context, readme: dict) -> list[str]:
    """Seconds from `python train.py` to a final evaluation at the target, per fresh seed (`time_to_result_cell`)."""
    reports = [ctx.json(f) for f in readme["time_to_result_files"]]
    first = reports[0]
    dates = sorted({r["date"] for r in reports})
    return [f"UR5e reach, seconds to a policy at >= {100 * first['target']:.0f} % reached, fresh seeds, compiling and the "
            f"final evaluation included (`{' '.join([first['preset'], *first.get('train_options', [])])}`, training "
            f"stopped at {100 * first['stop_at']:.1f} %; "
            f"{dates[0] if len(dates) == 1 else dates[0] + ' to ' + dates[-1]})", "", "",
            time_to_result_cell(reports, readme["cache_cold_seeds"])]


def _baseline_rows(ctx: Context) -> dict:
    return {(r["robot"], r["agent"], r["action"], r["target_radius"]): r
            for r in ctx.json("baselines/baselines.json")["rows"]}


def baselines_table(ctx: Context) -> list[list[str]]:
    rows = [["robot", "agent", "action mode", "target radius", "paper: reached", "reached", "paper: self collision",
             "self collision", "distance (m)"], ["---", "---", "---", "---:", "---:", "---:", "---:", "---:", "---:"]]
    for r in ctx.json("baselines/baselines.json")["rows"]:
        s = r["summary"]
        paper = PAPER_BASELINES.get((r["agent"], r["target_radius"])) if (r["robot"], r["action"]) == ("ur5e", "absolute") else None
        rows.append([r["robot"], r["agent"], r["action"], f"{r['target_radius']:g} m",
                     paper_pct(paper["target_reached"]) if paper else "", pct(s["target_reached"]),
                     paper_pct(paper["self_collision"]) if paper else "", pct(s["self_collision"]),
                     f"{s['distance']['mean']:.3f}"])
    return rows


def workspace_table(ctx: Context) -> list[list[str]]:
    rows = [["training workspace", "evaluation workspace", "paper: reached", "reached", "paper: self collision",
             "self collision", "paper: distance (m)", "distance (m)"], ["---", "---", "---:", "---:", "---:", "---:", "---:", "---:"]]
    for r in ctx.json("workspaces/workspace_generalization.json")["rows"]:
        s, p = r["summary"], PAPER_WORKSPACE[(r["trained"], r["evaluated"])]
        rows.append([WORKSPACE_NAMES[r["trained"]], WORKSPACE_NAMES[r["evaluated"]],
                     rate(p["target_reached"], p["target_reached_std"]), pct(s["target_reached"]),
                     rate(p["self_collision"], p["self_collision_std"]), pct(s["self_collision"]),
                     f"{p['distance']:.3f}", f"{s['distance']['mean']:.3f}"])
    return rows


def obstacle_table(ctx: Context) -> list[list[str]]:
    rows = [["trained radius (m)", "evaluated radius (m)", "paper: reached / self / obstacle", "reached", "self collision",
             "obstacle collision"], ["---", "---", "---:", "---:", "---:", "---:"]]
    for r in ctx.json("obstacle_size/obstacle_size.json")["rows"]:
        s, p = r["summary"], PAPER_OBSTACLE[(r["trained"], r["evaluated"])]
        paper = " / ".join(f"{100 * p[m]:.1f}" for m in ("target_reached", "self_collision", "obstacle_collision"))
        rows.append([r["trained"], f"{r['evaluated']:g}", paper + " %",
                     pct(s["target_reached"]), pct(s["self_collision"]), pct(s["obstacle_collision"])])
    return rows


def env_throughput_table(ctx: Context) -> list[list[str]]:
    rows = [["env", "envs", "env steps/s", "bare MJX ceiling", "fraction", "paper (RTX 3090 Ti)"],
            ["---", "---:", "---:", "---:", "---:", "---:"]]
    for r in ctx.json("throughput/env_throughput.json")["rows"]:
        paper = PAPER_THROUGHPUT.get(r["env"]) if r["num_envs"] == 8192 else None
        rows.append([r["env"], f"{r['num_envs']:,}", thousands(r["steps_per_s"]), thousands(r["ceiling_steps_per_s"]),
                     f"{100 * r['fraction_of_ceiling']:.0f} %", thousands(paper) if paper else ""])
    return rows


def cpu_backends_table(ctx: Context) -> list[list[str]]:
    """The two physics backends on a CPU (benchmarks/cpu_backends.py): env steps/s and start-up."""
    report = ctx.json("throughput/cpu_backends.json")
    rows = [["env", "envs", "MJX env steps/s", "native env steps/s", "native / MJX", "MJX start-up", "native start-up"],
            ["---", "---:", "---:", "---:", "---:", "---:", "---:"]]
    by_key = {(r["env"], r["num_envs"], r["backend"]): r for r in report["rates"]}
    for (env, n, backend), r in by_key.items():
        m = by_key.get((env, n, "mjx"))
        if backend != "mujoco" or m is None:
            continue
        rows.append([env, f"{n:,}", f"{m['env_steps_per_s']:,.1f}", f"{r['env_steps_per_s']:,.0f}",
                     f"{r['env_steps_per_s'] / m['env_steps_per_s']:,.0f}x", f"{m['startup_s']:.0f} s",
                     f"{r['startup_s']:.0f} s"])
    return rows


def train_throughput_table(ctx: Context) -> list[list[str]]:
    rows = [["GPUs", "envs", "batch", "training env steps/s", "env only", "fraction of env only", "speed-up"],
            ["---:", "---:", "---:", "---:", "---:", "---:", "---:"]]
    for r in ctx.json("throughput/train_throughput.json")["rows"]:
        env_only = r.get("env_only_steps_per_s")
        rows.append([str(r["devices"]), f"{r['num_envs']:,}", f"{r['batch_size']:,}", thousands(r["train_steps_per_s"]),
                     thousands(env_only) if env_only else "", f"{100 * r['fraction_of_env_only']:.1f} %" if env_only else "",
                     f"{r['speedup_vs_1_device']:.2f}x"])
    return rows


def brax_table(ctx: Context) -> list[list[str]]:
    d = ctx.json("throughput/brax_reference.json")
    rows = [["env steps", "ours: reached", "ours: self collision", "Brax: reached", "Brax: self collision"],
            ["---:", "---:", "---:", "---:", "---:"]]
    for ours, brax in zip(d["ours"]["evals"], d["brax"]["evals"]):
        rows.append([f"{ours['env_steps']:,}", f"{100 * ours['target_reached']:.1f} %", f"{100 * ours['self_collision']:.1f} %",
                     f"{100 * brax['target_reached']:.1f} %", f"{100 * brax['self_collision']:.1f} %"])
    rows.append(["training env steps/s", thousands(d["ours"]["steps_per_s"]), "", thousands(d["brax"]["steps_per_s"]),
                 f"ours {d['speedup']:.2f}x"])
    return rows


def failures_table(ctx: Context) -> list[list[str]]:
    rows = [["policy", "episodes", "reached", "self collision", "obstacle collision", "missed", "file"],
            ["---", "---:", "---:", "---:", "---:", "---:", "---"]]
    for listed in ctx.index["failures"]["rows"]:
        label, file = listed["label"], listed["file"]
        s = ctx.json(file)["summary"]
        o = s["outcomes"]
        cell = lambda k: f"{100 * o[k]:.1f} %" if k in o else ""  # noqa: E731
        rows.append([label, str(s["episodes"]), cell("reached"), cell("self collision"), cell("obstacle collision"),
                     cell("missed"), ctx.link(file)])
    return rows


# ------------------------------------------------------------------------------------------------
# The index: every paper table, figure and headline row beside ours.

def _gpu(device: str | None) -> str:
    """'NVIDIA H200' from eval.py's 'GPU (NVIDIA H200)' (other spellings as they are; None: '')."""
    m = re.fullmatch(r"GPU \((.*)\)", device or "")
    return m.group(1) if m else (device or "")


def _seeds_gpu(seeds, gpus) -> str:
    """'5; NVIDIA H200' (seeds; GPU models), '3/5; NVIDIA H100 80GB HBM3, NVIDIA H200' for several."""
    return "; ".join(["/".join(map(str, sorted(set(seeds)))), ", ".join(sorted(set(gpus)))])


def _json_seeds_gpu(ctx: Context, file: str, summary: dict | None = None) -> str:
    """Seeds and GPU of a JSON file: the units of its first evaluation's (or `summary`'s) target rate, its device."""
    data = ctx.json(file)
    summary = summary or data["evaluations"][0]["summary"]
    return _seeds_gpu([summary["target_reached"]["units"]], [_gpu(data.get("device"))])


def _experiment_seeds_gpu(ctx: Context, name: str, run: str | None = None) -> str:
    """The seeds evaluated per row of an experiment's table.json (or of one run's rows) and the GPU models that
    trained them, read from the parts' eval.json (their `provenance`, else their `device`)."""
    file = f"experiments/{name}/table.json"
    if not os.path.exists(os.path.join(ctx.results, file)):
        return ""
    rows = [r for r in ctx.json(file)["rows"] if run is None or r.get("run") == run]
    seeds = [r["seeds_evaluated"] for r in rows if r.get("per_seed")]
    gpus = []
    for row in rows:
        exp, _, folder = row.get("folder", "").removeprefix("runs/experiments/").partition("/")
        for part in sorted(glob.glob(os.path.join(ctx.results, "experiments", exp, "runs", folder, "seeds-*", "eval.json"))):
            with open(part, encoding="utf-8") as f:
                ev = json.load(f)
            gpus.append(_gpu(ev.get("provenance", {}).get("device") or ev.get("device")))
    return _seeds_gpu(seeds, [g for g in gpus if g])


def _eval_cell(ctx: Context, file: str) -> str:
    ev = ctx.evaluation(file)
    return f"{pct(ev['summary']['target_reached'])} / {collisions(ev)}"


def index_table(ctx: Context) -> list[list[str]]:
    rows = [["paper", "paper's number", "ours", "seeds; GPU", "command", "file"],
            ["---", "---:", "---:", "---", "---", "---"]]
    for run in runs(ctx, "headline"):
        ev = ctx.evaluation(run.file)
        command = f"python train.py {run.preset or train_config(ev)['preset']} --seeds 5"
        if ev["policy"]["env_steps"] < 0.98 * train_config(ev)["num_timesteps"]:  # stopped before its schedule's end
            command += f" --stop-after-steps {ev['policy']['env_steps']}"
        paper = PAPER_ROWS[run.paper]
        rows.append([f"Results: {run.label}", f"{paper_pct(paper['target_reached'])} / {paper_collisions(run.paper)}",
                     _eval_cell(ctx, run.file), _json_seeds_gpu(ctx, run.file), f"`{command}`", ctx.link(run.file)])
    listed = ctx.index["index"]
    for row in listed["experiment_rows"]:  # a paper row that one run of a registered experiment answers
        key, name, run = row["paper"], row["experiment"], row["run"]
        paper = PAPER_ROWS[key]
        rows.append([row["label"], f"{paper_pct(paper['target_reached'])} / {paper_collisions(key)}",
                     _experiment_ours(ctx, name, run=run), _experiment_seeds_gpu(ctx, name, run),
                     f"`python -m tools.experiments launch {name}`", ""])
    b = _baseline_rows(ctx)
    for radius in (0.01, 0.02):
        s = b[("ur5e", "pseudo_ik", "absolute", radius)]["summary"]
        rows.append([f"Table \"reaching baselines\": pseudo-IK, {radius * 100:g} cm target (UR5e, absolute control)",
                     f"{paper_pct(PAPER_BASELINES[('pseudo_ik', radius)]['target_reached'])} reached", pct(s["target_reached"]) + " reached",
                     _json_seeds_gpu(ctx, "baselines/baselines.json", s), "`python -m tools.paper_tables --tables baselines --num-envs 4096 --seeds 5`",
                     ctx.link("baselines/baselines.json")])
    rows.append(["Table \"action space\": precision of absolute vs relative control", paper_action_space(),
                 _experiment_ours(ctx, "action-space", precision=True), _experiment_seeds_gpu(ctx, "action-space"),
                 "`python -m tools.experiments launch action-space`", ""])
    ws = {(r["trained"], r["evaluated"]): r["summary"] for r in ctx.json("workspaces/workspace_generalization.json")["rows"]}
    p = PAPER_WORKSPACE[("full", "full-range")]
    rows.append(["Table \"workspace generalization\" (13 pairs), e.g. Full on Full Range",
                 f"{paper_pct(p['target_reached'])} reached", pct(ws[("full", "full-range")]["target_reached"]) + " reached",
                 _json_seeds_gpu(ctx, "workspaces/workspace_generalization.json", ws[("full", "full-range")]),
                 "`python -m tools.paper_tables --tables workspace --workspace ...`", ctx.link("workspaces/README.md")])
    ob = {(r["trained"], r["evaluated"]): r["summary"] for r in ctx.json("obstacle_size/obstacle_size.json")["rows"]}
    p = PAPER_OBSTACLE[("reach", 0.3)]
    rows.append(["Table \"obstacle size\" (14 pairs), e.g. a reach agent on a 0.3 m obstacle",
                 f"{paper_pct(p['target_reached'])} reached, {paper_pct(p['obstacle_collision'])} obstacle",
                 f"{pct(ob[('reach', 0.3)]['target_reached'])} reached, {pct(ob[('reach', 0.3)]['obstacle_collision'])} obstacle",
                 _json_seeds_gpu(ctx, "obstacle_size/obstacle_size.json", ob[("reach", 0.3)]),
                 "`python -m tools.paper_tables --tables obstacle --obstacle ...`", ctx.link("obstacle_size/README.md")])
    env = {r["env"]: r for r in ctx.json("throughput/env_throughput.json")["rows"] if r["num_envs"] == 8192}
    for name in ("ur5e-reach", "ur5e-reach-avoid"):
        rows.append([f"Simulation performance: {name} env steps/s, 8,192 envs", thousands(PAPER_THROUGHPUT[name]),
                     thousands(env[name]["steps_per_s"]), ctx.json("throughput/env_throughput.json")["meta"]["device"],
                     "`python -m benchmarks.env_throughput --sizes 8192`",
                     ctx.link("throughput/env_throughput.json")])
    for figure in listed["figures"]:  # a figure file and the command that draws it
        label, file, command = figure["label"], figure["file"], f"`{figure['command']}`"
        experiment = re.fullmatch(r"experiments/([\w.-]+)/curves.png", file)
        rows.append([label, "(figure)", "(figure)", _experiment_seeds_gpu(ctx, experiment.group(1)) if experiment else "",
                     command, ctx.link(file)])
    for figure in listed["experiment_figures"]:  # a figure that a registered experiment draws
        label, name = figure["label"], figure["experiment"]
        rows.append([label, "(figure)", _experiment_ours(ctx, name), _experiment_seeds_gpu(ctx, name),
                     f"`python -m tools.experiments launch {name}`", ""])
    return rows


# ------------------------------------------------------------------------------------------------
# The registered experiments (tools/experiment_registry.py): their budgets, the paper's finding and ours from the
# table.json each build writes under results/experiments/<name>/.

def _experiment_ours(ctx: Context, name: str, precision: bool = False, run: str | None = None) -> str:
    """Each row's target-reached rate (mean ± sample std over seeds), or with `precision` its distance, steps in target
    and exits from the target (the action-space table's columns), from the experiment's table.json; with `run`,
    only that run's rows (its own and its cross-evaluations)."""
    file = f"experiments/{name}/table.json"
    if not os.path.exists(os.path.join(ctx.results, file)):
        return "not run"
    cells = []
    for row in ctx.json(file)["rows"]:
        if run is not None and row.get("run") != run:
            continue
        values = row.get("per_seed", {}).get("target_reached")
        if not values and "cross" in row:
            continue  # a cross-evaluation not made yet (`tools.experiments list` says which parts are left)
        if not values:
            cells.append(f"{row['label']}: not done")
            continue
        partly = f" ({len(values)} of {row['seeds']} seeds)" if len(values) < row.get("seeds", 0) else ""
        if precision:
            mean = row["mean"]
            cells.append(f"{row['label']}: {mean['distance']:.3f} m, {mean['steps_in_target']:.1f}, "
                         f"{mean['times_left_target']:.2f}{partly}")
        else:
            cells.append(f"{row['label']}: {_seed_rate(values) if len(values) > 1 else f'{100 * values[0]:.1f} %'} "
                         f"reached{partly}")
    return "; ".join(cells) + f" ({ctx.link(f'experiments/{name}/table.md')})"


def experiments_table(ctx: Context) -> list[list[str]]:
    rows = [["experiment", "paper", "paper's finding", "runs x seeds, env steps", "ours", "seeds; GPU", "command"],
            ["---", "---", "---", "---:", "---", "---", "---"]]
    for name, exp in EXPERIMENTS.items():
        seeds = sorted({r.seeds for r in exp.runs})
        steps = sum(r.seeds * r.budget() for r in exp.runs)
        rows.append([f"`{name}`", exp.paper_ref, exp.paper,
                     f"{len(exp.runs)} x {'/'.join(map(str, seeds))}, {steps / 1e9:.2f}B",
                     _experiment_ours(ctx, name), _experiment_seeds_gpu(ctx, name), f"`python -m tools.experiments launch {name}`"])
    return rows


# ------------------------------------------------------------------------------------------------

TABLES: dict[str, Callable[[Context], list[list[str]]]] = {
    "index": index_table,
    "experiments": experiments_table,
    "readme": readme_table,
    "headline": listed_table("headline"),
    "baselines": baselines_table,
    "discount": listed_table("discount"),
    "joint_limit": listed_table("joint_limit"),
    "observations": listed_table("observations"),
    "action_scale": listed_table("action_scale"),
    "other_levers": listed_table("other_levers"),
    "lr_schedule": listed_table("lr_schedule"),
    "sac_grad_steps": listed_table("sac_grad_steps"),
    "sac_entropy": listed_table("sac_entropy"),
    "sac_cpu": listed_table("sac_cpu"),
    "sampled_actions": sampled_table,
    "workspaces": workspace_table,
    "obstacle_size": obstacle_table,
    "env_throughput": env_throughput_table,
    "cpu_backends": cpu_backends_table,
    "train_throughput": train_throughput_table,
    "brax_reference": brax_table,
    "failures": failures_table,
}

MARKER = re.compile(r"(<!-- table:([\w-]+) -->\n)(.*?)(<!-- /table -->)", re.S)


def fill(text: str, ctx: Context, tables=TABLES) -> str:
    """`text` with every marked table regenerated."""
    def replace(m: re.Match) -> str:
        name = m.group(2)
        if name not in tables:
            raise ValueError(f"table {name!r} is unknown: allowed are {', '.join(sorted(tables))}.")
        return m.group(1) + markdown(tables[name](ctx)) + "\n" + m.group(4)
    return MARKER.sub(replace, text)


def markdown_files(root: str) -> list[str]:
    """The files that may hold generated tables."""
    files = [os.path.join(root, "README.md"), os.path.join(root, "results", "README.md")]
    files += sorted(glob.glob(os.path.join(root, "results", "*", "README.md")))
    return [f for f in files if os.path.exists(f)]


def update(root: str = ROOT, tables=TABLES, check: bool = False) -> list[str]:
    """Regenerates the tables of every file under `root`; returns the files that changed (with
    `check`, the files that would change, written nowhere)."""
    ctx, changed = Context(root), []
    for path in markdown_files(root):
        with open(path, encoding="utf-8") as f:
            old = f.read()
        ctx.md_dir = os.path.dirname(path)
        new = fill(old, ctx, tables)
        if new != old:
            changed.append(os.path.relpath(path, root))
            if not check:
                with open(path, "w", encoding="utf-8") as f:
                    f.write(new)
    return changed


def main(argv=None) -> int:
    p = argparse.ArgumentParser(prog="python -m tools.results_index", description=__doc__.split("\n\n")[0])
    p.add_argument("--check", action="store_true", help="write nothing; exit 1 if a table differs from its JSON files")
    p.add_argument("--root", default=ROOT, help="repository root (default: this checkout)")
    args = p.parse_args(argv)
    changed = update(args.root, check=args.check)
    for path in changed:
        print(f"{'out of date' if args.check else 'rewrote'}: {path}", file=sys.stderr)
    return 1 if args.check and changed else 0


if __name__ == "__main__":
    sys.exit(main())
