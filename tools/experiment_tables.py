"""An experiment's table and figure, built from its runs' evaluations: `table.md` and `table.json` (one row per
run and per cross-evaluation, the paper's numbers beside ours, mean ± sample std over seeds and the mean's 95 %
confidence interval) and `curves.png` (training
curves from metrics.csv) in `<out>/<experiment>/`. A build first records each finished part's config.json,
eval.json, metrics.csv and cross-*.json in `<out>/<experiment>/runs/<run>/seeds-*/`: the evidence behind the table.
"""

from __future__ import annotations

import collections
import datetime
import functools
import json
import os
import statistics

from agents.checkpoint import write_atomic
from agents.evaluation import COLUMNS, EXTRA_COLUMNS
from agents.provenance import code_version
from tools.experiment_spec import Cross, Experiment, Run
from tools.results_cells import seed_stats
from tools.experiment_state import (
    TIMING_COLUMNS, RunState, cross_path, millions, record_folder, run_state, table_metrics,
)

RATE_METRICS = ("target_reached", "self_collision", "obstacle_collision")
"""Metrics shown as percentages (rates in [0, 1] in eval.json and in `Run.paper`)."""


def fmt_metric(metric: str, values) -> str:
    """'95.7 ± 0.4 % [95.3, 96.0]' for rates, '0.005 ± 0.001 [0.004, 0.006]' for others (sample std over seeds and
    the mean's 95 % confidence interval, `results_cells.seed_stats`; one seed: its value)."""
    values = [values] if isinstance(values, (int, float)) else values
    if metric in RATE_METRICS:
        return seed_stats(values, 1, 100.0, " %")
    return seed_stats(values, {name: d for name, _, d in COLUMNS + EXTRA_COLUMNS}.get(metric, 3))


def header(metric: str) -> str:
    return TIMING_COLUMNS.get(metric) or {name: h for name, h, _ in COLUMNS + EXTRA_COLUMNS}.get(metric, metric)


def describe_overrides(run: Run) -> str:
    """'algo.q_hidden_sizes=512x512, env.observation=joint_pos+ee_pos, num_timesteps=100M': sizes joined by x,
    names by +; the budget where the run sets one other than its preset's."""
    def value(v) -> str:
        if isinstance(v, (tuple, list)):
            return ("+" if all(isinstance(x, str) for x in v) else "x").join(map(str, v))
        return str(v)

    parts = [f"{k}={value(v)}" for k, v in run.overrides.items()]
    if run.budget() != run.preset_budget():
        parts.append(f"num_timesteps={millions(run.num_timesteps)}")
    return ", ".join(parts)


def merged_evaluation(state: RunState, files: dict[str, str] | None = None) -> dict:
    """The done parts' eval.json (or the given files: {part name: path}, for the parts they name) merged:
    {"env_steps" (the fewest), "eval_envs", "seeds", "per_seed": {metric: [value per seed, by seed]}}."""
    merged: dict = {"per_seed": {}, "seeds": 0}
    parts = [p for p in state.done_parts if files is None or p.name in files]
    for part in parts:
        path = files[part.name] if files is not None else os.path.join(part.logdir, "eval.json")
        with open(path) as f:
            ev = json.load(f)
        keep = state.run_seeds(part)  # a shared part's seeds beyond this run's are left out
        merged["env_steps"] = min(merged.get("env_steps", ev["env_steps"]), ev["env_steps"])
        merged["eval_envs"] = ev["eval_envs"]
        merged["seeds"] += keep
        if ev.get("device"):  # eval.json files written before the device was recorded lack it
            merged.setdefault("devices", []).extend([ev["device"]] * keep)  # one per seed
        if ev.get("source"):  # a part recorded from an earlier train.py run: the eval.py file it was made from
            merged.setdefault("sources", []).append(ev["source"]["eval_json"])
        for name, values in ev["per_seed"].items():
            merged["per_seed"].setdefault(name, []).extend(values[:keep])
    return merged


def cross_files(state: RunState, cross: Cross, record: str | None) -> dict[str, str]:
    """{part name: its cross-<name>.json} for the done parts that have one (of a done or a partial run). Fewer
    than the done parts: the others were not evaluated where their checkpoints were."""
    record_dir = record_folder(record, *state.owner) if record else None
    paths = {part.name: cross_path(part, cross, record_dir) for part in state.done_parts}
    return {name: path for name, path in paths.items() if path is not None}


def timing_cell(state: RunState, metric: str) -> str:
    """Wall-clock of one training process (mean over the parts) or env steps/s per seed; parts of different
    seed counts get one speed each ("500,000 (2 seeds) / 800,000 (1 seed)")."""
    parts = state.done_parts
    if metric == "wall_clock":
        return f"{state.wall_seconds:,.0f}" if state.wall_seconds > 0 else ""
    by_count: dict[int, list[float]] = {}
    for p in parts:
        if p.rate is not None:
            by_count.setdefault(p.count, []).append(p.rate)
    if len(by_count) == 1:
        return f"{statistics.mean(next(iter(by_count.values()))):,.0f}"
    return " / ".join(f"{statistics.mean(r):,.0f} ({n} seed{'s' if n > 1 else ''})" for n, r in sorted(by_count.items()))


def build_default(experiment: Experiment, states: list[RunState], out_dir: str, code: str | None = None) -> list[str]:
    """table.md and table.json (one row per run: the paper's numbers beside ours, mean ± sample std over seeds of
    the driver's evaluation) and curves.png (training curves from metrics.csv) in `out_dir`."""
    code = code or code_version()  # before anything is written (a written file would mark the tree modified)
    rows, table = [], []
    metrics, keys = list(experiment.metrics), table_metrics()

    def add(cells: list, row: dict, paper: dict, ev: dict | None, st: RunState, planned: int, timing: bool = True) -> None:
        """The metric cells (the paper's beside ours) of one row; `ev` None: not done; timing: the run's training
        wall-clock and speed in the timing columns."""
        if ev is not None:
            row.update(env_steps=ev["env_steps"], eval_envs=ev["eval_envs"], seeds_evaluated=ev["seeds"],
                       per_seed={}, mean={})
        for m in metrics:
            if m in TIMING_COLUMNS:
                cells += ["", timing_cell(st, m) if ev is not None and timing else ""]
                continue
            values = ev["per_seed"].get(keys[m]) if ev is not None else None
            if values is not None and len(values) != ev["seeds"]:  # a metric some parts' evaluations lack
                values = None
            cells += [fmt_metric(m, paper[m]) if m in paper else "", fmt_metric(m, values) if values is not None else ""]
            if values is not None:
                row["per_seed"][m] = values
                row["mean"][m] = sum(values) / len(values)
        if ev is None:
            cells[-1] = f"not done ({row['status']})"
        seeds = f"{ev['seeds']} x {ev['eval_envs']}" if ev is not None else f"{planned} x -"
        cells.append(seeds + (f" ({planned} planned)" if ev is not None and ev["seeds"] < planned else ""))
        devices = ev.get("devices", []) if ev is not None and timing else []
        cells.append(", ".join(f"{d} ({n} of {ev['seeds']})" if n < ev["seeds"] else d
                               for d, n in collections.Counter(devices).items()))
        if devices:
            row["devices"] = devices
        rows.append(cells)
        table.append(row)

    for st in states:
        run = st.run
        row = {"run": run.name, "label": run.title, "preset": run.preset, "overrides": run.overrides,
               "seeds": run.seeds, "num_timesteps": st.budget, "status": st.status, "folder": st.folder,
               "shared": st.shared, "paper": run.paper}
        if st.done_parts:  # a partial run's row holds its done seeds (the seeds x episodes column says how many)
            row.update(wall_seconds=st.wall_seconds, steps_per_second=st.rate,
                       parts=[{"seeds": p.name, "env_steps": p.steps, "wall_seconds": p.wall_seconds,
                               "steps_per_second_per_seed": p.rate} for p in st.done_parts])
        overrides = describe_overrides(run)
        cells = [run.title, f"`{run.preset}`" + (f" {overrides}" if overrides else "")]
        evaluated = merged_evaluation(st) if st.done_parts else None
        if evaluated and evaluated.get("sources"):
            row["sources"] = evaluated["sources"]
        add(cells, row, run.paper, evaluated, st, run.seeds)
    by_name = {st.run.name: st for st in states}
    for cross in experiment.cross:
        st = by_name[cross.run]
        files = cross_files(st, cross, os.path.dirname(out_dir))
        label = cross.label or f"{st.run.title} on {cross.name}"
        status = ("not evaluated" if not files and st.done_parts else st.status if not files else
                  "done" if st.status == "done" and len(files) == len(st.done_parts) else "partly evaluated")
        row = {"run": cross.run, "cross": cross.name, "label": label, "env": cross.env, "paper": cross.paper,
               "stochastic": cross.stochastic, "seeds": st.run.seeds, "status": status}
        cells = [label, f"`{cross.run}`'s policies, evaluated with {cross.setting}"]
        add(cells, row, cross.paper, merged_evaluation(st, files) if files else None, st, st.run.seeds, timing=False)
    head = (["run", "preset and overrides"] + [h for m in metrics for h in (f"paper: {header(m)}", header(m))]
            + ["seeds x episodes", "device (where training ended)"])
    keep = [i for i in range(len(head)) if not head[i].startswith(("paper: ", "device")) or any(r[i] for r in rows)]
    lines = [f"# {experiment.title}", "", f"Paper: {experiment.paper_ref}." + (f" {experiment.paper}" if experiment.paper else ""), ""]
    if experiment.note:
        lines += [experiment.note, ""]
    lines += ["| " + " | ".join(head[i] for i in keep) + " |", "|" + "---|" * len(keep)]
    lines += ["| " + " | ".join(r[i] for i in keep) + " |" for r in rows]
    budget = ", ".join(f"{st.run.name} {st.run.seeds} x {millions(st.budget)}" for st in states)
    command = f"python -m tools.experiments launch {experiment.name}"
    shared = [f"{st.run.name} trains in {st.shared}" for st in states if st.shared]
    earlier = [f"{r['run']} from {', '.join(r['sources'])}" for r in table if r.get("sources")]
    lines += ["", "Ours: the deterministic policy's evaluation at the end of training (the runs' eval.json; "
              "a cross row: the setting its second column names), mean ± sample std over seeds and in brackets "
              "the mean's 95 % stratified-bootstrap confidence interval (rliable); rates in %, "
              "distances in m. Each run's config.json, eval.json and metrics.csv per part (the "
              "seeds trained in one process): `runs/<run>/seeds-<first>-<last>/` beside this table"
              + (f" ({'; '.join(shared)}: the same training config, trained once)" if shared else "") + ".",
              f"Runs (seeds x env steps): {budget}.", f"Command: `{command}`."
              + (f" Recorded from an earlier `train.py` run (the `eval.py` evaluation of its final checkpoint): "
                 f"{'; '.join(earlier)}." if earlier else ""),
              f"Code {code}, built {datetime.date.today().isoformat()}.", ""]
    os.makedirs(out_dir, exist_ok=True)
    written = [os.path.join(out_dir, "table.md"), os.path.join(out_dir, "table.json")]
    with open(written[0], "w") as f:
        f.write("\n".join(lines))
    data = {"experiment": experiment.name, "title": experiment.title, "paper_ref": experiment.paper_ref,
            "paper": experiment.paper, "command": command, "code": code,
            "date": datetime.date.today().isoformat(), "rows": table}
    with open(written[1], "w") as f:
        json.dump(data, f, indent=2)
    figure = training_figure(experiment, states, os.path.join(out_dir, "curves.png"))
    return written + ([figure] if figure else [])


def training_figure(experiment: Experiment, states: list[RunState], path: str) -> str | None:
    """curves.png of the runs with a metrics.csv, a row per `curve_groups` row (else one), a panel per curve and
    axis (None without matplotlib, curves or logs)."""
    try:
        import matplotlib  # noqa: F401
    except ImportError:
        return None
    from tools import plots

    logged = {st.run.name: (st.run.title, [p.logdir for p in st.done_parts
                                           if os.path.isfile(os.path.join(p.logdir, "metrics.csv"))]) for st in states}
    rows = experiment.curve_groups or (("", tuple(logged)),)
    groups = {title: {logged[name][0]: logged[name][1] for name in names if name in logged and logged[name][1]}
              for title, names in rows}
    groups = {title: runs for title, runs in groups.items() if runs}
    if not experiment.curves or not groups:
        return None
    present = [m for m in experiment.curves
               if all(m in plots.read_metrics(d) for runs in groups.values() for ds in runs.values() for d in ds)]
    if not present:
        return None
    keep = {p.logdir: st.run_seeds(p) for st in states for p in st.done_parts}  # the seeds each table row averages
    fig = plots.curve_grid(groups, present, experiment.curve_axes, path, experiment.title, keep=keep)
    import matplotlib.pyplot as plt

    plt.close(fig)
    return path


RECORDED_FILES = ("config.json", "eval.json", "metrics.csv")
"""What a build copies of each finished part into the results, with its cross-*.json (checkpoints stay in the
runs folder)."""


def record_parts(state: RunState, record: str, only: str | None = None) -> list[str]:
    """Copies the files of the run's finished parts (or of the part named `only`) into the record folder of the
    run whose folder it trains in (`record_folder`), so that the results hold the evidence behind the table and
    the next checkout sees those parts done."""
    written = []
    target_dir = record_folder(record, *state.owner)
    for part in state.done_parts:
        if only is not None and part.name != only:
            continue
        target = os.path.join(target_dir, part.name)
        if os.path.abspath(part.logdir) == os.path.abspath(target):
            continue
        os.makedirs(target, exist_ok=True)
        crosses = sorted(n for n in os.listdir(part.logdir) if n.startswith("cross-") and n.endswith(".json"))
        for name in RECORDED_FILES + tuple(crosses):
            if os.path.isfile(os.path.join(part.logdir, name)):
                with open(os.path.join(part.logdir, name)) as f:
                    write_atomic(os.path.join(target, name), f.read())  # readers see the old file or the new
                written.append(os.path.join(target, name))
    return written


def record(selection, runs_dir: str, out: str, registry: dict | None = None) -> list[str]:
    """Records the finished parts of every selected run (`record_parts`), built table or not: what a GPU call
    brings back is `out`. Each file once, though runs sharing a folder both record it."""
    return list(dict.fromkeys(path for exp, runs in selection for r in runs
                              for path in record_parts(run_state(exp, r, runs_dir, out, registry), out)))


def build(selection, runs_dir: str, out: str, complete_only: bool = False, log=print, registry: dict | None = None) -> list[str]:
    """Builds each selected experiment's table and figure into `<out>/<experiment>/`, after recording its runs'
    finished parts there (with `complete_only`, only experiments whose runs are all done); returns the files
    written."""
    written, code = [], code_version()  # once: the first table written would mark the tree modified
    for exp, _ in selection:
        states = [run_state(exp, r, runs_dir, out, registry) for r in exp.runs]
        if not any(st.done_parts for st in states) or (complete_only and any(st.status != "done" for st in states)):
            continue
        files = [f for st in states for f in record_parts(st, out)]
        states = [run_state(exp, r, runs_dir, out, registry) for r in exp.runs]
        builder = exp.builder or functools.partial(build_default, code=code)
        files += builder(exp, states, os.path.join(out, exp.name))
        for path in files:
            log(f"wrote {path}")
        written += files
    return written
