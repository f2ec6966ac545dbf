"""Pictures and tables from runs: training curves (tools/plots.py) and the paper's cross-evaluation tables
(tools/paper_tables.py).
"""

import json
import os

import numpy as np
import pytest

from agents import evaluation
from eval_runs import untrained_export
from tools import paper_tables, plots


def test_training_curves_from_train_logs(point_run, tmp_path):
    steps, mean, std, seeds = plots.curve([str(point_run)], "episode/target_reached")
    rows = plots.read_metrics(str(point_run))
    assert seeds == 2
    assert list(steps) == [5120, 10240]
    at_end = rows["episode/target_reached"][rows["env_steps"] == 10240]
    np.testing.assert_allclose(mean[-1], at_end.mean())
    np.testing.assert_allclose(std[-1], at_end.std())
    out = tmp_path / "curves.png"
    fig = plots.training_curves({"ppo": str(point_run)}, out=str(out))
    assert out.stat().st_size > 10_000
    assert len(fig.axes) == 2  # target reached and return (point mass has no collisions)
    assert [t.get_text() for t in fig.legends[0].get_texts()] == ["ppo (2 seeds)"]
    renderer = fig.canvas.get_renderer()
    legend_box = fig.legends[0].get_window_extent(renderer)
    assert legend_box.x0 > fig.axes[-1].get_window_extent(renderer).x1  # beside the panels, over no curve
    assert legend_box.x1 < fig.bbox.x1  # the figure widened to hold it
    with pytest.raises(ValueError, match="metrics.csv"):
        plots.read_metrics(str(tmp_path))


def test_training_curves_against_wall_clock(tmp_path):
    # Two seeds logged over three chunks; the x value is the seeds' mean running sum of chunk times.
    rows = [(100, 0, 2.0, 0.1), (100, 1, 4.0, 0.3), (200, 0, 1.0, 0.5), (200, 1, 1.0, 0.7),
            (300, 0, 3.0, 0.9), (300, 1, 1.0, 0.9)]
    (tmp_path / "metrics.csv").write_text("env_steps,seed,steps_per_second,wall_seconds,episode/target_reached\n"
                                          + "".join(f"{s},{d},1.0,{w},{v}\n" for s, d, w, v in rows))
    seconds, mean, _, seeds = plots.curve(str(tmp_path), "episode/target_reached", x="wall_clock")
    np.testing.assert_allclose(seconds, [3.0, 4.0, 6.0])  # seed 0: 2, 3, 6; seed 1: 4, 5, 6
    np.testing.assert_allclose(mean, [0.2, 0.6, 0.9])
    assert seeds == 2
    # Only the first seed (a run sharing a larger run's part): seed 0's values and clock alone.
    seconds, mean, std, seeds = plots.curve(str(tmp_path), "episode/target_reached", x="wall_clock",
                                            keep={str(tmp_path): 1})
    np.testing.assert_allclose(seconds, [2.0, 3.0, 6.0])
    np.testing.assert_allclose(mean, [0.1, 0.5, 0.9])
    assert seeds == 1
    assert not std.any()
    fig = plots.training_curves({"run": str(tmp_path)}, ["episode/target_reached"], x="wall_clock")
    assert fig.axes[0].get_xlabel() == plots.X_AXES["wall_clock"]
    with pytest.raises(ValueError, match="x='minutes'.*env_steps, wall_clock"):
        plots.curve(str(tmp_path), "episode/target_reached", x="minutes")
    # A run resumed from its step-100 checkpoint logs steps 200 and 300 again (4 s each): they replace the first rows.
    with open(tmp_path / "metrics.csv", "a") as f:
        f.write("200,0,1.0,4.0,0.5\n300,0,1.0,4.0,0.7\n200,1,1.0,4.0,0.5\n300,1,1.0,4.0,0.7\n")
    seconds, mean, _, _ = plots.curve(str(tmp_path), "episode/target_reached", x="wall_clock")
    np.testing.assert_allclose(seconds, [3.0, 7.0, 11.0])  # seed 0: 2, 6, 10; seed 1: 4, 8, 12
    np.testing.assert_allclose(mean, [0.2, 0.5, 0.7])


def test_paper_tables_from_given_checkpoints_and_skips_the_rest(point_run, tmp_path, capsys):
    written = paper_tables.main(["--tables", "action", "workspace", "obstacle", "--out", str(tmp_path),
                                 "--num-envs", "16", "--action", f"relative={point_run}"])
    assert [os.path.basename(p) for p in written] == ["action_space.md"]
    err = capsys.readouterr().err
    assert "skipped table 'workspace'" in err
    assert "skipped table 'obstacle'" in err
    assert "no 'absolute' checkpoint given, row skipped" in err
    text = (tmp_path / "action_space.md").read_text()
    assert "| Relative | 2 x 16 |" in text
    assert "Position" not in text
    assert str(point_run) in text
    assert "device: CPU" in text
    assert "--action relative=" in text
    data = json.loads((tmp_path / "action_space.json").read_text())
    assert data["rows"][0]["role"] == "relative"
    assert data["rows"][0]["policy"]["env_steps"] == 10240
    with pytest.raises(ValueError, match="role 'diagonal' is unknown"):
        paper_tables.main(["--tables", "workspace", "--workspace", f"diagonal={point_run}", "--out", str(tmp_path)])


def test_paper_tables_evaluate_each_pair_on_the_right_env_config(arm_export, tmp_path, monkeypatch):
    """The workspace and obstacle cross-evaluations: which env config each (trained, evaluated) row
    gets (evaluation itself replaced by a recorder)."""
    calls = []

    def record(policy, env_name, config, num_envs, eval_seeds, last_steps=10, progress=None):
        calls.append((policy.name, env_name, config))
        per_env = {k: np.zeros((1, 2)) for k in ("target_reached", "self_collision", "obstacle_collision", "distance")}
        return evaluation.Result(policy, env_name, config, 2, list(eval_seeds), 10, [{"metrics": {}}], per_env, 0.0)

    monkeypatch.setattr(evaluation, "run", record)
    front = untrained_export(tmp_path / "front", workspace="front", init_range="limited")
    full = untrained_export(tmp_path / "full", init_range="limited")
    paper_tables.main(["--tables", "workspace", "--out", str(tmp_path), "--workspace", f"front={front}", f"full={full}"])
    rows = [(name.split("/")[-2], cfg.workspace, cfg.target_sampling, cfg.init_range) for name, _, cfg in calls]
    assert rows == [
        ("front", "front", "reachable", "limited"), ("full", "full", "reachable", "limited"),  # own workspace
        ("front", "full", "reachable", "limited"),  # the paper's "Full" agent: limited initial range
        ("front", "pandagym", "uniform", "limited"), ("full", "pandagym", "uniform", "limited"),
        ("full", "upper", "reachable", "limited"), ("full", "full", "reachable", "full"),  # -> "Full Range"
    ]
    table = (tmp_path / "workspace_generalization.md").read_text()
    assert "| Front | Full | 1 x 2 |" in table
    assert "| Full | Full Range | 1 x 2 |" in table

    calls.clear()
    avoid = untrained_export(tmp_path / "avoid", "ur5e-reach-avoid", obstacle_radius=0.1, target_radius=0.02)
    paper_tables.main(["--tables", "obstacle", "--out", str(tmp_path), "--obstacle", f"0.1={avoid}",
                       f"reach={arm_export}"])
    got = [(name.split("/")[-2], env_name, cfg.obstacle_radius, cfg.target_radius, len(cfg.observation))
           for name, env_name, cfg in calls]
    assert got[0] == ("avoid", "ur5e-reach-avoid", 0.1, 0.02, 6)
    # The reach agent on the reach-avoid env: its own 4-part observation, the reach-avoid runs' target.
    reach = arm_export.parent.name  # arm0, or arm1 where the worker made another "arm" folder first
    assert got[1:] == [(reach, "ur5e-reach-avoid", r, 0.02, 4) for r in (0.025, 0.05, 0.1, 0.2, 0.3)]
    assert calls[1][2].substeps == 2  # the reach checkpoint's own settings otherwise
