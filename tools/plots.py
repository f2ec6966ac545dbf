"""Pictures: training curves from train.py logs, and the environment seen (matplotlib, PNG).

Functions for notebooks (each returns the matplotlib Figure, and writes a PNG if `out` is given):

    from tools import plots
    plots.training_curves({"front": "runs/front", "full": ["runs/full_a", "runs/full_b"]}, out="curves.png")
    plots.initial_state({"ur5e-reach-avoid": {}}, seed=0, out="initial_state.png")
    plots.target_scatter("ur5e-reach", out="targets.png")

Command line (the PNGs under results/figures/ were made with these, on a CPU):

    python -m tools.plots curves runs/front runs/full --labels front full --out results/figures/curves.png
    python -m tools.plots curves runs/sac runs/ppo --labels SAC PPO --x wall_clock --out curves_seconds.png
    python -m tools.plots env --out results/figures

A rollout video is `python eval.py ... --video PATH` (envs/render.py).
"""

from __future__ import annotations

import argparse
import csv
import os
import sys
import textwrap

import numpy as np

from tools import run_cli

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))

CURVE_METRICS = {  # the first four are drawn by default
    "episode/target_reached": "target reached",
    "episode/self_collision": "self collision",
    "episode/obstacle_collision": "obstacle collision",
    "episode/return": "episode return",
    "episode/distance": "final distance to target (m)",
}
"""Columns of metrics.csv drawn by default, with their axis titles (the paper's figures)."""


def pyplot():
    import matplotlib

    if not os.environ.get("DISPLAY") and matplotlib.get_backend().lower() not in ("agg", "module://matplotlib_inline.backend_inline"):
        matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    return plt


def read_metrics(logdir: str) -> dict[str, np.ndarray]:
    """metrics.csv of a train.py logdir as {column: float array} (empty cells are NaN)."""
    path = logdir if logdir.endswith(".csv") else os.path.join(logdir, "metrics.csv")
    if not os.path.isfile(path):
        raise ValueError(f"{path!r} does not exist: allowed is a train.py logdir (with metrics.csv) or a metrics.csv.")
    with open(path, newline="") as f:
        rows = list(csv.DictReader(f))
    if not rows:
        raise ValueError(f"{path!r} has no rows.")
    return {k: np.array([float(r[k]) if r.get(k) not in ("", None) else np.nan for r in rows]) for k in rows[0]}


X_AXES = {
    "env_steps": "env steps",
    "wall_clock": "training wall-clock (s)",
}
"""Horizontal axes of the curves: env steps per seed, or the running sum of the logged chunk times
(`wall_seconds`: compilation included, less what ran beside the state's initialisation; start-up, checkpoint saves
and the final evaluation not).
Compare wall-clock curves only between runs made alone on one device of one kind."""


def curve(logdirs, metric: str, x: str = "env_steps",
          keep: dict | None = None) -> tuple[np.ndarray, np.ndarray, np.ndarray, int]:
    """(x values, mean, std, number of seeds) of `metric` over every seed of every logdir.

    Seeds of one run are the `seed` column; several runs (e.g. one per seed) are pooled. Steps
    logged by only some seeds are dropped, so every point averages the same seeds. With
    x="wall_clock" the x values are the seeds' mean running training time at those steps.
    `keep`: logdir -> how many of its seeds to draw, its lowest seed numbers (a run whose part
    holds more, shared with a larger run: the seeds its table averages); a logdir not in it: all."""
    if x not in X_AXES:
        raise ValueError(f"x={x!r} is not a curve axis: allowed are {', '.join(X_AXES)}.")
    logdirs = [logdirs] if isinstance(logdirs, str) else list(logdirs)
    series, chunks = {}, {}
    for i, logdir in enumerate(logdirs):
        m = read_metrics(logdir)
        if metric not in m:
            raise ValueError(f"metric {metric!r} is not in {logdir}/metrics.csv: allowed are "
                             f"{', '.join(k for k in m if k not in ('env_steps', 'seed'))}.")
        seconds = m.get("wall_seconds", np.full(len(m["env_steps"]), np.nan))
        drawn = set(sorted(set(m["seed"].tolist()))[:(keep or {}).get(logdir)])
        for step, seed, value, chunk in zip(m["env_steps"], m["seed"], m[metric], seconds):
            if seed not in drawn:
                continue
            # A resumed run logs the steps it redoes again: the last row of a step counts.
            series.setdefault((i, seed), {})[step] = value
            chunks.setdefault((i, seed), {})[step] = chunk
    common = sorted(set.intersection(*(set(s) for s in series.values())))
    values = np.array([[s[step] for step in common] for s in series.values()])
    if x == "env_steps":
        xs = np.array(common)
    else:
        clocks = [dict(zip(sorted(c), np.cumsum([c[step] for step in sorted(c)]))) for c in chunks.values()]
        xs = np.array([[clock[step] for step in common] for clock in clocks]).mean(0)
    return xs, np.nanmean(values, 0), np.nanstd(values, 0), len(series)


LEGEND_CHARS = 50
"""A legend label's longest line (characters) in the training-curve figures; longer labels wrap."""
LEGEND_CHAR_INCHES, LEGEND_MARGIN_INCHES = 0.062, 0.8
"""The legend column's width: per character of the longest label line at font size 8, and for the line marker."""


def training_curves(runs: dict, metrics=None, out: str | None = None, title: str | None = None, band: float = 1.0,
                    x: str = "env_steps"):
    """One panel per metric, one line per run (label -> logdir or list of logdirs): the mean over
    seeds against env steps (or x="wall_clock", see X_AXES), with a band of `band` standard
    deviations across seeds."""
    defaults = list(CURVE_METRICS)[:4]
    metrics = metrics or [m for m in defaults if all(m in read_metrics(_first(d)) for d in runs.values())]
    return curve_grid({"": runs}, metrics, (x,), out, title, band)


def curve_grid(groups: dict, metrics, axes=("env_steps",), out: str | None = None, title: str | None = None,
               band: float = 1.0, keep: dict | None = None):
    """One row of panels per group (row title -> {label: logdir or list of logdirs}), one panel per metric and
    horizontal axis (X_AXES) in each row: runs that belong together (fast SAC and PPO on one task) share their
    panels, against env steps and against wall-clock side by side. `keep`: logdir -> how many of its seeds to
    draw (`curve`'s)."""
    plt = pyplot()
    from matplotlib.ticker import EngFormatter

    for x in axes:
        if x not in X_AXES:
            raise ValueError(f"axes={tuple(axes)!r} holds {x!r}: allowed are {', '.join(X_AXES)}.")
    columns = [(metric, x) for metric in metrics for x in axes]
    panels, height = 4.2 * len(columns), 3.4 * len(groups)
    fig, grid = plt.subplots(len(groups), len(columns), figsize=(panels, height), squeeze=False)
    for row, (group, runs) in zip(grid, groups.items()):
        for ax, (metric, x) in zip(row, columns):
            for name, logdirs in runs.items():
                steps, mean, std, n = curve(logdirs, metric, x, keep)
                line, = ax.plot(steps, mean, label=f"{name} ({n} seed{'s' if n > 1 else ''})")
                if n > 1 and band > 0:
                    ax.fill_between(steps, mean - band * std, mean + band * std, color=line.get_color(), alpha=0.2, lw=0)
            ax.set_title(": ".join(t for t in (group, CURVE_METRICS.get(metric, metric)) if t))
            ax.set_xlabel(X_AXES[x])
            if x == "env_steps":
                ax.xaxis.set_major_formatter(EngFormatter(sep=""))
            ax.grid(alpha=0.3)
            if metric in ("episode/target_reached", "episode/self_collision", "episode/obstacle_collision"):
                ax.set_ylim(-0.02, 1.02)
    if title:
        fig.suptitle(title)
    # Each row's legend goes right of its panels, where it hides no curve and squeezes no panel; the figure widens
    # by the longest label line.
    legends = [(row[0].get_legend_handles_labels(), row) for row in grid]
    lines = [line for (_, labels), _ in legends for label in labels for line in textwrap.wrap(label, LEGEND_CHARS)]
    width = panels + (LEGEND_MARGIN_INCHES + LEGEND_CHAR_INCHES * max(map(len, lines)) if lines else 0.0)
    fig.set_size_inches(width, height)
    fig.tight_layout(rect=(0, 0, panels / width, 1))
    for (handles, labels), row in legends:
        if labels:
            box = row[-1].get_position()
            fig.legend(handles, [textwrap.fill(label, LEGEND_CHARS) for label in labels], loc="center left",
                       fontsize=8, bbox_to_anchor=(box.x1 + 0.1 / width, (box.y0 + box.y1) / 2), frameon=False)
    return save(fig, out)


def _first(logdirs):
    return logdirs if isinstance(logdirs, str) else list(logdirs)[0]


def save(fig, out, dpi: int = 110):
    if out:
        if os.path.dirname(out):
            os.makedirs(os.path.dirname(out), exist_ok=True)
        fig.savefig(out, dpi=dpi)
        print(f"wrote {out}", file=sys.stderr)
    return fig


def initial_state(setups: dict, seed: int = 0, out: str | None = None, width: int = 640, height: int = 480,
                  workspace_alpha: float = 0.12):
    """Rendered initial states (robot, target in green, obstacle in red, the full workspace in
    translucent grey), one panel per env: {env name: env options}. The target is drawn enlarged
    (`envs.render.TARGET_MARKER_RADIUS`), as in the paper's figure."""
    import jax

    import envs
    from envs import render

    plt = pyplot()
    fig, axes = plt.subplots(1, len(setups), figsize=(width / 100 * len(setups), height / 100), squeeze=False)
    for ax, (name, options) in zip(axes[0], setups.items()):
        env = envs.make(name, **options)
        state = jax.jit(env.reset)(jax.random.PRNGKey(seed))
        ax.imshow(render.render_state(env, state, width=width, height=height, workspace_alpha=workspace_alpha))
        extra = ", ".join(f"{k}={v}" for k, v in options.items())
        ax.set_title(name + (f" ({extra})" if extra else ""), fontsize=9)
        ax.axis("off")
    fig.tight_layout()
    return save(fig, out)


def sample_targets(env_name: str, workspace: str, num: int = 3000, seed: int = 0, **options) -> np.ndarray:
    """`num` targets (num, 3) as the env samples them for `workspace` (pure-JAX kinematics; the
    `pandagym` cube needs uniform sampling, which is used there)."""
    import jax

    import envs

    if workspace == "pandagym":
        options.setdefault("target_sampling", "uniform")
    env = envs.make(env_name, workspace=workspace, **options)
    sample = jax.jit(jax.vmap(env.sample_target))
    targets, _, ok = sample(jax.random.split(jax.random.PRNGKey(seed), num))
    return np.asarray(targets)[np.asarray(ok)]


def target_scatter(env_name: str = "ur5e-reach", workspaces=("pandagym", "front", "upper", "full"), num: int = 2000,
                   seed: int = 0, out: str | None = None, **options):
    """The paper's target-distribution figure: targets as the env samples them (reachable: the end
    effector of a random collision-free pose), one column per workspace, seen from above (x-y) and
    from the side (x-z); the base is at the origin, the circle is the robot's reach."""
    import envs

    plt = pyplot()
    robot = envs.make(env_name).robot
    center, reach = np.asarray(robot.workspace_center, float), float(robot.reach)
    fig, axes = plt.subplots(2, len(workspaces), figsize=(3.2 * len(workspaces), 6.4), squeeze=False)
    for col, ws in enumerate(workspaces):
        pts = sample_targets(env_name, ws, num, seed, **options)
        for row, (i, j, names) in enumerate(((0, 1, ("x", "y")), (0, 2, ("x", "z")))):
            ax = axes[row][col]
            ax.scatter(pts[:, i], pts[:, j], s=1.5, alpha=0.35, c=pts[:, 2], cmap="viridis", vmin=center[2] - reach,
                       vmax=center[2] + reach, rasterized=True)
            ax.add_patch(plt.Circle((center[i], center[j]), reach, fill=False, ls="--", lw=0.8, color="grey"))
            ax.plot([0], [0], "k^", ms=6)
            ax.set_xlim(-1.05, 1.05)
            ax.set_ylim(center[j] - 1.05 if j == 2 else -1.05, center[j] + 1.05 if j == 2 else 1.05)
            ax.set_aspect("equal")
            ax.set_xlabel(f"{names[0]} (m)")
            ax.set_ylabel(f"{names[1]} (m)")
            ax.grid(alpha=0.3)
            if row == 0:
                ax.set_title(f"{ws} ({len(pts)} targets)", fontsize=10)
    fig.suptitle(f"{env_name}: sampled targets per workspace, top (x-y) and side (x-z) views; colour = height")
    fig.tight_layout()
    return save(fig, out, dpi=90)


def main(argv=None):
    p = argparse.ArgumentParser(prog="python -m tools.plots", description="Training curves and environment figures.")
    sub = p.add_subparsers(dest="what", required=True)
    c = sub.add_parser("curves", help="training curves from train.py logdirs")
    c.add_argument("logdirs", nargs="+", help="train.py logdirs (one line each; join several with commas to pool them)")
    c.add_argument("--labels", nargs="+", help="one label per logdir argument (default: the paths)")
    c.add_argument("--metrics", nargs="+", help=f"metrics.csv columns (default: {', '.join(CURVE_METRICS)} where present)")
    c.add_argument("--x", default="env_steps", choices=list(X_AXES), help="horizontal axis (default: env_steps)")
    c.add_argument("--title")
    c.add_argument("--out", required=True)
    e = sub.add_parser("env", help="initial-state renders and target scatter")
    e.add_argument("--out", default=os.path.join(ROOT, "results", "figures"))
    e.add_argument("--seed", type=int, default=0)
    e.add_argument("--num-targets", type=int, default=2000)
    args = p.parse_args(argv)
    if args.what == "curves":
        labels = args.labels or args.logdirs
        if len(labels) != len(args.logdirs):
            raise ValueError(f"--labels has {len(labels)} entries for {len(args.logdirs)} logdirs: allowed is one each.")
        training_curves({lab: d.split(",") for lab, d in zip(labels, args.logdirs)}, args.metrics, args.out, args.title,
                        x=args.x)
    else:
        initial_state({"ur5e-reach-avoid": {}, "panda-reach-avoid": {}}, args.seed,
                      os.path.join(args.out, "initial_state_reach_avoid.png"))
        target_scatter("ur5e-reach", num=args.num_targets, seed=args.seed,
                       out=os.path.join(args.out, "targets_ur5e.png"))
        target_scatter("panda-reach", num=args.num_targets, seed=args.seed,
                       out=os.path.join(args.out, "targets_panda.png"))


if __name__ == "__main__":
    run_cli(main)
