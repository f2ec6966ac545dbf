"""The building blocks of the results tables (tools/results_index.py): the paper's numbers, the cached reader of
results/ (`Context`), the cell formatters, and the tables of eval.py runs (a `Run` per row, its cells picked from
`COLUMNS`). The tables themselves and the command line are in tools/results_index.py."""

from __future__ import annotations

import dataclasses
import functools
import json
import os
import statistics
from typing import Callable

from agents import intervals
from agents.eval_stats import sample_std
from tools.experiment_spec import paper_row, paper_table

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
INDEX = "index.json"
"""The results' own index, relative to results/: which file makes which row of each table."""

# ------------------------------------------------------------------------------------------------
# The paper's numbers (assets/paper_numbers.json; rates in [0, 1]). Nothing of ours is typed in there.

PAPER_ROWS = {r["run"]: r for r in paper_table("reach") + paper_table("reach_avoid")}
"""The paper's headline rows by name: target_reached, self_collision and (reach-avoid) obstacle_collision."""
PAPER_BASELINES = {(r["agent"], r["target_radius"]): r for r in paper_table("baselines")}
PAPER_WORKSPACE = {(r["trained"], r["evaluated"]): r for r in paper_table("workspace")}
PAPER_OBSTACLE = {(r["trained"], r["evaluated"]): r for r in paper_table("obstacle_size")}
PAPER_THROUGHPUT = {r["env"]: r["env_steps_per_second"] for r in paper_table("simulation_performance")}
PAPER_OBSERVATION = {r["task"]: r["parts"] for r in paper_table("observation")}


def paper_action_space() -> str:
    """'absolute: 0.012 m, 41.5 steps in target, 21.7 exits; relative: 0.005 m, 99.1, 0.05' (the precision table)."""
    a, r = (paper_row("action_space", control=c) for c in ("absolute", "relative"))
    return (f"absolute: {a['distance']:g} m, {a['steps_in_target']:g} steps in target, {a['times_left_target']:g} exits; "
            f"relative: {r['distance']:g} m, {r['steps_in_target']:g}, {r['times_left_target']:g}")


# ------------------------------------------------------------------------------------------------
# Reading the JSON files and formatting cells.

class Context:
    """Reads JSON files under `<root>/results` once; `md_dir` is the directory of the file being written
    (links are relative to it)."""

    def __init__(self, root: str):
        self.root, self.results = root, os.path.join(root, "results")
        self.md_dir = self.results
        self._cache: dict[str, dict] = {}

    def json(self, file: str) -> dict:
        if file not in self._cache:
            with open(os.path.join(self.results, file), encoding="utf-8") as f:
                self._cache[file] = json.load(f)
        return self._cache[file]

    @property
    def index(self) -> dict:
        """results/index.json: each table's rows (and a table of eval.py runs its columns) by the table's name."""
        return self.json(INDEX)

    def evaluation(self, file: str) -> dict:
        """The first evaluation of an eval.py JSON file; each summary entry gains "unit_values", its per-seed
        values (for the confidence interval), where every unit reports the metric."""
        ev = self.json(file)["evaluations"][0]
        for name, stats in ev["summary"].items():
            values = [unit["metrics"].get(name) for unit in ev.get("units", [])]
            if values and None not in values:
                stats.setdefault("unit_values", values)
        return ev

    def link(self, file: str) -> str:
        path = os.path.relpath(os.path.join(self.results, file), self.md_dir).replace(os.sep, "/")
        return f"[{os.path.basename(file)}]({path})"


@functools.lru_cache(maxsize=None)
def _interval(values: tuple[float, ...]) -> list[float] | None:
    return intervals.mean_ci(values)


def ci(values, digits: int = 1, scale: float = 100.0) -> str:
    """' [95.3, 96.0]': rliable's 95 % bootstrap confidence interval of the mean over seeds (times `scale`: a rate
    in %); '' for one seed."""
    interval = _interval(tuple(float(v) for v in values))
    return f" [{scale * interval[0]:.{digits}f}, {scale * interval[1]:.{digits}f}]" if interval else ""


def seed_stats(values, digits: int, scale: float = 1.0, unit: str = "") -> str:
    """'95.7 ± 0.4 % [95.3, 96.0]': the mean over seeds ± their sample std (ddof 1), the unit, and the mean's 95 %
    confidence interval; one seed: its value. Every table of per-seed values formats them with this."""
    values = [float(v) for v in values]
    mean = statistics.mean(values)
    if len(values) < 2:
        return f"{scale * mean:.{digits}f}{unit}"
    return f"{scale * mean:.{digits}f} ± {scale * statistics.stdev(values):.{digits}f}{unit}" + ci(values, digits, scale)


def pct(stats: dict | None) -> str:
    """'95.7 ± 0.4 % [95.3, 96.0]' (mean ± sample std over trained seeds, and the mean's 95 % confidence interval
    where the seeds' values are known); one seed: '95.7 %'."""
    if not stats:
        return ""
    if stats.get("units", 2) < 2:
        return f"{100 * stats['mean']:.1f} %"
    return f"{100 * stats['mean']:.1f} ± {100 * sample_std(stats):.1f} %" + ci(stats.get("unit_values", ()))


def rate(mean: float, std: float) -> str:
    return f"{100 * mean:.1f} ± {100 * std:.1f} %"


def millions(steps: int) -> str:
    return f"{steps / 1e6:.1f}M"


def thousands(rate_per_s: float) -> str:
    return f"{rate_per_s:,.0f}"


def time_to_result_cell(reports: list[dict], cold_seeds: list[int]) -> str:
    """benchmarks/time_to_result.py's `reports` of one setting: the seeds' wall clocks with the compilation cache
    filled, and those of `cold_seeds` (into an empty cache), and how many evaluations met the target."""
    if len({(r["preset"], r["target"], r["stop_at"], tuple(r.get("train_options", ()))) for r in reports}) != 1:
        raise ValueError("time-to-result reports differ in preset, target, stop_at or train options: allowed are "
                         "reports of one setting.")
    seeds = [s for r in reports for s in r["seeds"]]
    cells = []
    for label, group in (("with the compilation cache", [s for s in seeds if s["seed"] not in cold_seeds]),
                         ("into an empty one", [s for s in seeds if s["seed"] in cold_seeds])):
        if group:
            low, high = (f"{bound(s['wall_seconds'] for s in group):.0f}" for bound in (min, max))
            cells.append(f"{low if low == high else low + '-' + high} s {label} ({len(group)} "
                         f"seed{'s' if len(group) > 1 else ''})")
    return ", ".join(cells) + f"; {sum(s['reached_target'] for s in seeds)} of {len(seeds)} evaluations at the target"


def per_gpu_count(rows: list[dict]) -> str:
    """A train_throughput report's training rate per device count (no variants): "R1 on 1 GPU, R2 on 2", each R in
    env steps/s with thousands separators."""
    rates = [(r["devices"], thousands(r["train_steps_per_s"])) for r in rows if r.get("variant") is None]
    return ", ".join(f"{rate} on {n}" + (" GPU" if i == 0 else "") for i, (n, rate) in enumerate(rates))


def eval_wall_cell(report: dict) -> str:
    """eval.py's wall clock per process from a wall-clock report (`wall_seconds`: cold, cache[, cache2, ...])."""
    wall = report["wall_seconds"]
    cached = [v for k, v in wall.items() if k.startswith("cache")]
    low, high = min(cached), max(cached)
    return f"{low:.1f}{'' if low == high else f'-{high:.1f}'} s with the compilation cache, {wall['cold']:.1f} s into an empty one"


def eval_settings_cell(report: dict) -> str:
    """benchmarks/eval_settings.py's seconds per further setting in one process, in the order evaluated."""
    rows = report["settings"]
    further = ", ".join(f"{row['wall_seconds']:.1f}" for row in rows[1:])
    return f"{further} s per further {report['field']} ({rows[0]['wall_seconds']:.1f} s the first, loading the checkpoint)"


def paper_pct(value: float | None) -> str:
    """'96.1 %' from the paper's rate 0.961."""
    return "" if value is None else f"{100 * value:.1f} %"


def has_obstacle(ev: dict) -> bool:
    return "avoid" in ev["env_name"]


def collisions(ev: dict) -> str:
    s = ev["summary"]
    out = [pct(s["self_collision"]) + " self"]
    if has_obstacle(ev):
        out.append(pct(s["obstacle_collision"]) + " obstacle")
    return ", ".join(out)


def paper_collisions(key: str) -> str:
    row = PAPER_ROWS[key]
    return ", ".join([f"{paper_pct(row['self_collision'])} self"]
                     + ([f"{paper_pct(row['obstacle_collision'])} obstacle"] if "obstacle_collision" in row else []))


def added_observation(ev: dict) -> str:
    parts = ev["env_config"]["observation"]
    base = PAPER_OBSERVATION["reach-avoid" if has_obstacle(ev) else "reach"]
    extra = [p for p in parts if p not in base]
    return "the paper's" if not extra else "+ " + " + ".join(extra)


def train_config(ev: dict) -> dict:
    return ev["policy"].get("train_config") or {}


# ------------------------------------------------------------------------------------------------
# Tables of eval.py runs: one row per JSON file, columns picked from COLUMNS; results/index.json lists each
# table's columns and rows.

@dataclasses.dataclass(frozen=True)
class Run:
    """One row of a table of eval.py runs (a row of that table in results/index.json)."""
    label: str
    """The row's first cell: what this run is."""
    file: str
    """eval.py JSON, relative to results/."""
    paper: str = ""
    """Key of PAPER_ROWS for the paper's numbers of this row ("" if the paper has none)."""
    preset: str = ""
    """The preset that trains it today, where that is not the one its JSON names (trained before it existed)."""


Cell = Callable[[dict, Run, Context], str]
COLUMNS: dict[str, tuple[str, str, Cell]] = {  # key -> (header, alignment, cell)
    "run": ("run", "---", lambda ev, run, ctx: run.label),
    "preset": ("preset", "---", lambda ev, run, ctx: f"`{run.preset or train_config(ev).get('preset', '')}`"),
    "paper_reached": ("paper: reached", "---:", lambda ev, run, ctx: paper_pct(PAPER_ROWS[run.paper]["target_reached"]) if run.paper else ""),
    "paper_collisions": ("paper: collisions", "---:", lambda ev, run, ctx: paper_collisions(run.paper) if run.paper else ""),
    "reached": ("reached", "---:", lambda ev, run, ctx: pct(ev["summary"]["target_reached"])),
    "self": ("self collision", "---:", lambda ev, run, ctx: pct(ev["summary"]["self_collision"])),
    "obstacle": ("obstacle collision", "---:",
                 lambda ev, run, ctx: pct(ev["summary"]["obstacle_collision"]) if has_obstacle(ev) else ""),
    "collisions": ("collisions", "---:", lambda ev, run, ctx: collisions(ev)),
    "distance": ("distance (m)", "---:", lambda ev, run, ctx: f"{ev['summary']['distance']['mean']:.3f}"),
    "steps_in_target": ("steps in target", "---:", lambda ev, run, ctx: f"{ev['summary']['steps_in_target']['mean']:.1f}"),
    "times_left": ("times left target", "---:", lambda ev, run, ctx: f"{ev['summary']['times_left_target']['mean']:.2f}"),
    "env_steps": ("env steps per seed", "---:", lambda ev, run, ctx: millions(ev["policy"]["env_steps"])),
    "schedule": ("schedule (`--num-timesteps`)", "---:", lambda ev, run, ctx: millions(train_config(ev)["num_timesteps"])),
    "discount": ("discount", "---:", lambda ev, run, ctx: f"{train_config(ev)['algo']['discount']:g}"),
    "action_scale": ("action scale", "---:", lambda ev, run, ctx: f"{ev['env_config']['action_scale']:g}"),
    "w_joint_limit": ("`w_joint_limit`", "---:", lambda ev, run, ctx: f"{ev['env_config'].get('w_joint_limit', 0.0):g}"),
    "grad_steps": ("gradient steps per env step", "---:",
                   lambda ev, run, ctx: str(train_config(ev)["algo"]["grad_updates_per_step"])),
    "observation": ("observation", "---", lambda ev, run, ctx: added_observation(ev)),
    "actions": ("actions", "---", lambda ev, run, ctx: ev.get("actions", "deterministic")),
    "episodes": ("seeds x episodes", "---:", lambda ev, run, ctx: f"{ev['summary']['target_reached']['units']} x {ev['num_envs']}"),
    "file": ("file", "---", lambda ev, run, ctx: ctx.link(run.file)),
}


@dataclasses.dataclass(frozen=True)
class EvalTable:
    columns: tuple[str, ...]
    runs: tuple[Run, ...]

    def __call__(self, ctx: Context) -> list[list[str]]:
        rows = [[COLUMNS[c][0] for c in self.columns], [COLUMNS[c][1] for c in self.columns]]
        for run in self.runs:
            ev = ctx.evaluation(run.file)
            rows.append([COLUMNS[c][2](ev, run, ctx) for c in self.columns])
        return rows


def runs(ctx: Context, table: str) -> tuple[Run, ...]:
    """The rows of `table` in results/index.json (a row's keys are Run's fields; an unknown key is an error)."""
    return tuple(Run(**row) for row in ctx.index[table]["rows"])


def listed_table(name: str) -> Callable[[Context], list[list[str]]]:
    """The table of eval.py runs `name` of results/index.json: an EvalTable of its columns and its rows."""
    def table(ctx: Context) -> list[list[str]]:
        return EvalTable(tuple(ctx.index[name]["columns"]), runs(ctx, name))(ctx)
    return table


def markdown(rows: list[list[str]]) -> str:
    """Header, alignment row and body rows as a markdown table."""
    return "\n".join("| " + " | ".join(r) + " |" if i != 1 else "|" + "|".join(r) + "|" for i, r in enumerate(rows))
