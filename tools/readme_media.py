"""The README's two pictures: an animation of shipped policies and the headline results against the paper's.

    python -m tools.readme_media animation --out results/figures/policies.gif
    python -m tools.readme_media headline --out results/figures/headline.png

`animation` renders one episode of each shipped policy named (default: UR5e and Panda reach-avoid, and the UR5e
among three moving obstacles) side by side with `envs.render` on the CPU: of `--envs` episodes of eval seed `--seed`,
the first in which the policy reaches the target (the first episode where none does). `headline` draws the paper's
target-reached rate of each headline row beside ours with the paper's stated settings (the `*-paper` presets) and
ours with the row's preset: the mean over trained seeds with its 95 % bootstrap interval (rliable, as the tables).
"""

from __future__ import annotations

import argparse
import os

import numpy as np

import envs
from agents import evaluation, intervals
from tools import plots, run_cli
from tools.results_cells import Context, runs
from tools.results_index import PAPER_ROWS, finished_experiment_row, paper_settings_seeds

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
SHOWN = ("ur5e-reach-avoid-ppo", "panda-reach-avoid-ppo", "ur5e-reach-avoid-ppo-moving3")
"""Shipped policies (results/checkpoints/) the animation shows by default, left to right."""
HEADLINE_ROWS = 5
"""The headline rows drawn: the paper's four PPO rows and its UR5e SAC row (the rest add observations)."""


# ------------------------------------------------------------------------------------------------
# The animation


def episode_frames(checkpoint: str, num_envs: int, seed: int, width: int, height: int) -> tuple[np.ndarray, dict, float]:
    """Frames (T, H, W, 3) of one episode of the policy export `checkpoint` on the env it was trained on (the first
    of `num_envs` episodes that reaches the target, else the first), that episode's metrics and the env step (s)."""
    from envs import render  # needs an OpenGL: imported where a picture is made, as eval.py does

    policy = evaluation.checkpoint_policy(checkpoint)
    config = envs.make_config(policy.train_env_name, policy.train_env_config)
    records = evaluation.rollout(policy, policy.train_env_name, config, num_envs, seed)
    reached = np.asarray(records["metrics"]["episode/target_reached"]) > 0
    i = int(np.argmax(reached)) if reached.any() else 0
    one = {key: value[:, i:i + 1] for key, value in records.items() if key not in ("length", "metrics")}
    one["length"] = records["length"][i:i + 1]
    one["metrics"] = {key: np.asarray(value)[i:i + 1] for key, value in records["metrics"].items()}
    env = envs.from_config(policy.train_env_name, config)
    frames = render.rollout_frames(env, one, width=width, height=height)
    return frames, {key: float(value[0]) for key, value in one["metrics"].items()}, env.dt


def side_by_side(clips: list[np.ndarray]) -> np.ndarray:
    """Clips (T_i, H, W_i, 3) joined left to right; a shorter clip holds its last frame."""
    steps = max(len(c) for c in clips)
    padded = [np.concatenate([c, np.repeat(c[-1:], steps - len(c), axis=0)]) for c in clips]
    return np.concatenate(padded, axis=2)


def animation(out: str, shown=SHOWN, num_envs: int = 8, seed: int = 0, width: int = 240, height: int = 180,
              every: int = 2) -> list[dict]:
    """Writes the GIF of `shown` (names under results/checkpoints/), every `every`-th env step at the real speed;
    returns each episode's metrics."""
    from envs import render

    clips, shown_metrics = [], []
    for name in shown:
        frames, metrics, dt = episode_frames(os.path.join(ROOT, "results", "checkpoints", name), num_envs, seed,
                                         width, height)
        clips.append(frames[::every])
        shown_metrics.append({"policy": name, **metrics})
    render.write_video(out, side_by_side(clips), fps=max(1, round(1.0 / (dt * every))))
    return shown_metrics


# ------------------------------------------------------------------------------------------------
# The headline figure


def headline_rows(ctx: Context) -> list[dict]:
    """Per headline row: its label, the paper's rate and our per-seed rates with the paper's settings (may be empty)
    and with the row's preset, from the files the README's table reads."""
    readme = ctx.index["readme"]
    from_experiments = {r["file"]: (r["experiment"], r["run"]) for r in readme["from_experiments"]}
    rows = []
    for run in runs(ctx, "headline")[:HEADLINE_ROWS]:
        settings = [seed["episode/target_reached"] for seed in
                    paper_settings_seeds(ctx, readme["paper_settings"][run.file])] \
            if run.file in readme["paper_settings"] else []
        experiment = finished_experiment_row(ctx, *from_experiments[run.file]) if run.file in from_experiments else None
        preset = (experiment["per_seed"]["target_reached"] if experiment else
                  ctx.evaluation(run.file)["summary"]["target_reached"]["unit_values"])
        rows.append({"label": run.label, "paper": PAPER_ROWS[run.paper]["target_reached"],
                     "paper_settings": settings, "preset": list(preset)})
    return rows


def headline_figure(rows: list[dict], out: str | None = None):
    """Horizontal rows of target-reached rates (%): the paper's (diamond), ours with its settings and ours with the
    preset (dots with the 95 % interval of the mean over seeds; a single seed without one)."""
    plt = plots.pyplot()
    fig, ax = plt.subplots(figsize=(8.5, 0.75 * len(rows) + 1.2))
    series = (("paper_settings", "ours, the paper's settings", "tab:orange", 0.15),
              ("preset", "ours, the row's preset", "tab:blue", -0.15))
    for y, row in enumerate(rows):
        ax.plot(100 * row["paper"], y, "kD", label="the paper" if y == 0 else None)
        for key, label, color, offset in series:
            values = np.asarray(row[key], float)
            if not values.size:
                continue
            mean, ci = 100 * values.mean(), intervals.mean_ci(values)
            err = None if ci is None else [[mean - 100 * ci[0]], [100 * ci[1] - mean]]
            ax.errorbar(mean, y + offset, xerr=err, fmt="o", color=color, capsize=3,
                        label=label if y == 0 else None)
            right = mean if ci is None else 100 * ci[1]
            ax.annotate(f"{len(values)} seed{'s' * (len(values) > 1)}", (right, y + offset), fontsize=7,
                        xytext=(6, -3), textcoords="offset points", color=color)
    ax.set_yticks(range(len(rows)), [r["label"] for r in rows], fontsize=8)
    ax.invert_yaxis()
    ax.set_xlabel("target reached (%): mean over trained seeds, 95 % bootstrap interval")
    ax.grid(axis="x", alpha=0.3)
    ax.legend(loc="lower center", bbox_to_anchor=(0.5, 1.0), ncol=3, fontsize=8, frameon=False)
    fig.tight_layout()
    return plots.save(fig, out)


def main(argv=None):
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    sub = p.add_subparsers(dest="what", required=True)
    a = sub.add_parser("animation", help="a GIF of shipped policies, side by side")
    a.add_argument("--out", required=True, help="the .gif to write")
    a.add_argument("--policies", nargs="+", default=list(SHOWN), help="names under results/checkpoints/")
    a.add_argument("--envs", type=int, default=8, help="episodes to pick a reaching one from")
    a.add_argument("--seed", type=int, default=0, help="eval seed")
    h = sub.add_parser("headline", help="the headline rows against the paper's")
    h.add_argument("--out", required=True, help="the .png to write")
    args = p.parse_args(argv)
    if args.what == "animation":
        missing = [n for n in args.policies if not os.path.isdir(os.path.join(ROOT, "results", "checkpoints", n))]
        if missing:
            raise ValueError(f"--policies {missing[0]!r} is not a shipped policy: allowed are "
                             f"{', '.join(sorted(os.listdir(os.path.join(ROOT, 'results', 'checkpoints'))))}.")
        if args.envs < 1:
            raise ValueError(f"--envs={args.envs} is invalid: allowed is an integer >= 1.")
        for m in animation(args.out, args.policies, args.envs, args.seed):
            print(f"{m['policy']}: reached {m['episode/target_reached']:.0f}, {m['episode/steps_in_target']:.0f} steps "
                  f"in the target, collisions {m['episode/self_collision'] + m.get('episode/obstacle_collision', 0):.0f}")
        print(f"wrote {args.out}")
    else:
        headline_figure(headline_rows(Context(ROOT)), args.out)


if __name__ == "__main__":
    run_cli(main)
