"""Writes results/experiments/README.md: the hand-written findings (`findings.md` beside it) followed by one
generated section per registered experiment (its paper reference, commands, and its rows, ours beside the
paper's, from the `table.json` its build wrote).

    python -m tools.experiment_index --write    # rewrite the README
    python -m tools.experiment_index --check    # exit 1 if the README differs from what --write would write

The registry (`tools.experiment_registry`) imports no jax; the cells' confidence intervals come from rliable
(`tools.results_cells.seed_stats`).
"""

from __future__ import annotations

import argparse
import json
import os
import re
import sys

from tools import run_cli
from tools.results_cells import seed_stats

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
DEFAULT_OUT = "results/experiments"

RATES = ("target_reached", "self_collision", "obstacle_collision")
"""Metrics in [0, 1], shown as percentages."""

COLUMNS = {  # metric -> (header, decimals); the tables' metrics besides the timing ones
    "target_reached": ("reached", 1),
    "self_collision": ("self collision", 1),
    "obstacle_collision": ("obstacle collision", 1),
    "distance": ("distance (m)", 3),
    "steps_in_target": ("steps in target", 1),
    "times_left_target": ("exits from the target", 2),
    "mean_joint_vel": ("mean joint speed (rad/s)", 2),
    "mean_joint_acc": ("mean joint acceleration (rad/s²)", 1),
}


def resolve(out_dir: str) -> str:
    """`out_dir` as an absolute path (a relative one is taken from the repository root)."""
    return out_dir if os.path.isabs(out_dir) else os.path.join(ROOT, out_dir)


def registered() -> dict:
    """The registry: experiment name -> Experiment."""
    import tools.experiment_registry  # noqa: F401  (registers the experiments)
    from tools.experiment_spec import EXPERIMENTS

    return EXPERIMENTS


def fmt(metric: str, values: list[float]) -> str:
    """'95.8 ± 0.3 % [95.5, 96.0]' for a rate, '0.019 ± 0.001 [0.018, 0.020]' otherwise (`results_cells.seed_stats`:
    sample std over seeds and the mean's 95 % confidence interval; one seed: the value)."""
    scale, unit = (100.0, " %") if metric in RATES else (1.0, "")
    return seed_stats(values, COLUMNS[metric][1], scale, unit)


def fmt_paper(metric: str, value: float) -> str:
    """The paper's number of a metric: '96.4 %' or '0.005'."""
    digits = COLUMNS[metric][1]
    return f"{100 * value:.{digits}f} %" if metric in RATES else f"{value:.{digits}f}"


def steps(row: dict) -> str:
    """'5 x 150M' (seeds evaluated x env steps per seed); '3 of 5 x 60M' for a partly evaluated row."""
    done, planned = row.get("seeds_evaluated") or 0, row.get("seeds") or 0
    seeds = f"{done} of {planned}" if done < planned else f"{done}"
    return f"{seeds} x {round(row['env_steps'] / 1e6):g}M"


def episodes(table: dict) -> str:
    """'4,096 episodes' (the evaluation's episodes a seed; several counts joined by '/')."""
    counts = sorted({row["eval_envs"] for row in table["rows"] if row.get("eval_envs")})
    return "/".join(f"{n:,}" for n in counts) + " episodes"


def metrics_of(experiment, table: dict) -> list[str]:
    """The table's metrics this index shows, in the experiment's order."""
    present = {m for row in table["rows"] for m in row.get("per_seed", {})}
    return [m for m in experiment.metrics if m in COLUMNS and m in present]


def cell(metric: str, row: dict) -> str:
    """Ours, with the paper's number after it where the paper has one."""
    values = row.get("per_seed", {}).get(metric)
    ours = fmt(metric, values) if values else ""
    paper = row.get("paper", {}).get(metric)
    return ours + (f" (paper {fmt_paper(metric, paper)})" if paper is not None else "")


def row_line(row: dict, metrics: list[str]) -> str:
    """One markdown row: label, seeds x steps, then a cell per metric."""
    if not row.get("per_seed"):
        return "| " + " | ".join([row["label"], row.get("status", "not done")] + [""] * len(metrics)) + " |"
    return "| " + " | ".join([row["label"], steps(row)] + [cell(m, row) for m in metrics]) + " |"


def rows_table(experiment, table: dict) -> list[str]:
    """The experiment's rows, ours beside the paper's, as markdown lines."""
    metrics = metrics_of(experiment, table)
    head = ["run", "seeds x env steps"] + [COLUMNS[m][0] for m in metrics]
    lines = ["| " + " | ".join(head) + " |", "|---|---:|" + "---:|" * len(metrics)]
    return lines + [row_line(row, metrics) for row in table["rows"]]


def read_table(out: str, name: str) -> dict | None:
    """`<out>/<name>/table.json`, or None before the experiment is built."""
    path = os.path.join(out, name, "table.json")
    if not os.path.isfile(path):
        return None
    with open(path, encoding="utf-8") as f:
        return json.load(f)


def note_anchor(findings: str, name: str) -> str | None:
    """The anchor of the findings' note on experiment `name` (a heading '### `name`'), or None."""
    if not re.search(rf"^### `{re.escape(name)}`\s*$", findings, re.M):
        return None
    return re.sub(r"[^a-z0-9 -]", "", name.lower()).replace(" ", "-")


def section(experiment, table: dict | None, out: str, findings: str = "") -> str:
    """One experiment's section: title, paper reference, commands, rows, links."""
    name = experiment.name
    lines = [f"### `{name}`: {experiment.title}", "", f"Paper: {experiment.paper_ref}."
             + (f" {experiment.paper}" if experiment.paper else ""), "",
             f"Commands: `python -m tools.experiments launch {name}` (train), "
             f"`python -m tools.experiments build {name}` (table and figure).", ""]
    if table is None:
        return "\n".join(lines + ["Not built yet.", ""])
    lines += rows_table(experiment, table) + [""]
    links = [f"[table.md]({name}/table.md)"]
    if os.path.isfile(os.path.join(out, name, "curves.png")):
        links.append(f"[curves.png]({name}/curves.png)")
    anchor = note_anchor(findings, name)
    if anchor:
        links.append(f"[notes](#{anchor})")
    built = f"; built at code {table['code']}, {table['date']}" if table.get("code") else ""
    lines += [f"Ours: mean ± sample std over seeds [the mean's 95 % confidence interval], {episodes(table)} a seed"
              f"{built}. " + ", ".join(links) + ".", ""]
    if experiment.note:
        lines += [experiment.note, ""]
    return "\n".join(lines)


def read_findings(out: str) -> str:
    """The hand-written part: `<out>/findings.md`."""
    with open(os.path.join(out, "findings.md"), encoding="utf-8") as f:
        return f.read()


def readme(out_dir: str = DEFAULT_OUT, experiments: dict | None = None) -> str:
    """The whole README: findings.md, then a generated section per registered experiment (or per `experiments`)."""
    out = resolve(out_dir)
    experiments = registered() if experiments is None else experiments
    findings = read_findings(out)
    parts = [findings.rstrip("\n"), "", "## The experiments", "",
             "Generated from the registry (`tools/experiment_registry.py`) and each experiment's `table.json` by "
             "`python -m tools.experiment_index --write`; edit `findings.md`, not this file.", ""]
    parts += [section(exp, read_table(out, name), out, findings) for name, exp in experiments.items()]
    return "\n".join(parts).rstrip("\n") + "\n"


def main(argv=None) -> int:
    """--write rewrites `<out>/README.md`; --check exits 1 where it differs from what --write would write."""
    p = argparse.ArgumentParser(prog="python -m tools.experiment_index", description=__doc__.split("\n\n")[0])
    mode = p.add_mutually_exclusive_group(required=True)
    mode.add_argument("--write", action="store_true", help="rewrite the README")
    mode.add_argument("--check", action="store_true", help="write nothing; exit 1 if the README is out of date")
    p.add_argument("--out", default=DEFAULT_OUT, help=f"the experiments' results folder (default: {DEFAULT_OUT})")
    args = p.parse_args(argv)
    path = os.path.join(resolve(args.out), "README.md")
    text = readme(args.out)
    old = open(path, encoding="utf-8").read() if os.path.isfile(path) else None
    if args.check:
        if old != text:
            print(f"out of date: {path} (python -m tools.experiment_index --write)", file=sys.stderr)
            return 1
        return 0
    if old != text:
        with open(path, "w", encoding="utf-8") as f:
            f.write(text)
        print(f"rewrote: {path}", file=sys.stderr)
    return 0


if __name__ == "__main__":
    run_cli(main)
