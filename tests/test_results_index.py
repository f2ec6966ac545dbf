"""tools/results_index.py: the tables it writes from hand-made eval.py JSON files, and its --check on this
repository (every committed table is the generated one; an edited cell is caught)."""

import dataclasses
import json
import os
import shutil

import pytest

from tools import results_cells as rc
from tools import results_index as ri

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))


def _stats(mean, std, units=5):
    return {"mean": mean, "std_units": std, "units": units}


def _eval_json(env_name, env_steps, reached, self_c, obstacle, discount):
    summary = {"target_reached": _stats(*reached), "self_collision": _stats(*self_c),
               "obstacle_collision": _stats(*obstacle), "distance": _stats(0.0204, 0.001)}
    return {"evaluations": [{
        "env_name": env_name, "num_envs": 4096, "env_config": {"observation": ["joint_pos"]},
        "policy": {"env_steps": env_steps, "train_config": {"preset": env_name + "-ppo", "algo": {"discount": discount}}},
        "summary": summary}]}


TINY = rc.EvalTable(("run", "discount", "env_steps", "reached", "self", "obstacle", "file"), (
    rc.Run("reach", "study/a_eval.json"),
    rc.Run("reach-avoid", "study/b_eval.json"),
))

README = """# A study

Text before.

<!-- table:tiny -->
stale
<!-- /table -->

Text after.
"""

EXPECTED = """# A study

Text before.

<!-- table:tiny -->
| run | discount | env steps per seed | reached | self collision | obstacle collision | file |
|---|---:|---:|---:|---:|---:|---|
| reach | 0.99 | 150.1M | 95.7 ± 0.5 % | 2.7 ± 0.1 % |  | [a_eval.json](a_eval.json) |
| reach-avoid | 0.97 | 8.2M | 86.8 ± 0.3 % | 3.5 ± 0.1 % | 2.3 ± 0.3 % | [b_eval.json](b_eval.json) |
<!-- /table -->

Text after.
"""


@pytest.fixture
def tiny_root(tmp_path):
    study = tmp_path / "results" / "study"
    study.mkdir(parents=True)
    (study / "a_eval.json").write_text(json.dumps(
        _eval_json("ur5e-reach", 150_077_440, (0.95708, 0.0041), (0.0270, 0.0012), (0.0, 0.0), 0.99)))
    (study / "b_eval.json").write_text(json.dumps(
        _eval_json("ur5e-reach-avoid", 8_192_000, (0.86753, 0.0031), (0.0349, 0.0011), (0.0231, 0.0029), 0.97)))
    (study / "README.md").write_text(README)
    return tmp_path


def test_writes_the_table_between_the_markers(tiny_root):
    path = tiny_root / "results" / "study" / "README.md"
    assert ri.update(str(tiny_root), {"tiny": TINY}, check=True) == ["results/study/README.md"]
    assert path.read_text() == README  # --check writes nothing
    assert ri.update(str(tiny_root), {"tiny": TINY}) == ["results/study/README.md"]
    assert path.read_text() == EXPECTED
    assert ri.update(str(tiny_root), {"tiny": TINY}, check=True) == []


def test_unknown_table_name_is_an_error(tiny_root):
    with pytest.raises(ValueError, match="'tiny' is unknown"):
        ri.update(str(tiny_root), {}, check=True)


def test_check_passes_on_the_committed_repository():
    assert ri.main(["--check", "--root", ROOT]) == 0


def test_check_fails_after_a_cell_is_edited(tmp_path):
    root = tmp_path / "repo"
    shutil.copytree(os.path.join(ROOT, "results"), root / "results", ignore=shutil.ignore_patterns("checkpoints", "runs"))
    shutil.copy(os.path.join(ROOT, "README.md"), root / "README.md")
    path = root / "results" / "headline" / "README.md"
    text = path.read_text()
    cell = rc.pct(rc.Context(str(root)).evaluation("headline/ur5e_reach_ppo_eval.json")["summary"]["target_reached"])
    assert f"| {cell} |" in text
    path.write_text(text.replace(f"| {cell} |", "| 99.9 ± 0.1 % |", 1))
    assert ri.main(["--check", "--root", str(root)]) == 1
    assert ri.main(["--root", str(root)]) == 0
    assert path.read_text() == text


def test_experiment_rows_for_the_readme_only_when_every_seed_is_evaluated(tmp_path):
    precise = {"distance": 0.005, "steps_in_target": 99.0, "times_left_target": 0.05}
    rows = [{"run": "done", "label": "done", "seeds": 2, "seeds_evaluated": 2, "per_seed": {"target_reached": [0.96, 0.97]},
             "mean": precise},
            {"run": "half", "label": "half", "seeds": 2, "seeds_evaluated": 1, "per_seed": {"target_reached": [0.9]},
             "mean": precise},
            {"run": "none", "label": "none", "seeds": 2, "status": "missing"},
            {"run": "done", "label": "done, sampled", "cross": "sampled", "seeds": 2, "seeds_evaluated": 1,
             "per_seed": {"target_reached": [1.0]}, "mean": precise},
            {"run": "half", "label": "half, sampled", "cross": "sampled", "seeds": 2}]
    folder = tmp_path / "results" / "experiments" / "x"
    folder.mkdir(parents=True)
    (folder / "table.json").write_text(json.dumps({"rows": rows}))
    ctx = rc.Context(str(tmp_path))
    assert ri.finished_experiment_row(ctx, "x", "done")["per_seed"]["target_reached"] == [0.96, 0.97]  # not the cross row
    assert ri.finished_experiment_row(ctx, "x", "half") is None
    assert ri.finished_experiment_row(ctx, "x", "absent") is None
    assert ri.finished_experiment_row(ctx, "not-built", "done") is None
    # the sample std 0.01 / sqrt(2); the bootstrap means of 2 seeds are 0.96, 0.965, 0.97: the interval is their range
    assert ri._seed_rate([0.96, 0.97]) == "96.5 ± 0.7 % [96.0, 97.0]"
    # The index's cell: every run row, and the cross rows that hold numbers.
    assert ri._experiment_ours(ctx, "x") == ("done: 96.5 ± 0.7 % [96.0, 97.0] reached; half: 90.0 % reached (1 of 2 seeds); "
                                             "none: not done; done, sampled: 100.0 % reached (1 of 2 seeds) "
                                             "([table.md](experiments/x/table.md))")
    assert ri._experiment_ours(ctx, "x", precision=True).startswith(
        "done: 0.005 m, 99.0, 0.05; half: 0.005 m, 99.0, 0.05 (1 of 2 seeds); none: not done; ")
    # One run's rows (a paper row that is one run of an experiment): its own row and its cross rows.
    assert ri._experiment_ours(ctx, "x", run="done") == ("done: 96.5 ± 0.7 % [96.0, 97.0] reached; done, sampled: 100.0 % reached "
                                                         "(1 of 2 seeds) ([table.md](experiments/x/table.md))")


def test_seeds_and_gpus_of_an_experiment_come_from_its_parts(tmp_path):
    """The index's `seeds; GPU` cell: each row's evaluated seeds, and the GPU models its parts' eval.json name (their
    `provenance`, else their `device`), the parts of a run trained in another experiment's folder included."""
    rows = [{"run": "a", "label": "a", "seeds": 3, "seeds_evaluated": 3, "folder": "runs/experiments/x/a",
             "per_seed": {"target_reached": [0.9, 0.9, 0.9]}},
            {"run": "b", "label": "b", "seeds": 5, "seeds_evaluated": 5, "folder": "runs/experiments/y/b",
             "per_seed": {"target_reached": [0.9] * 5}},
            {"run": "b", "cross": "c", "label": "b on c", "seeds": 5}]
    (tmp_path / "results" / "experiments" / "x").mkdir(parents=True)
    (tmp_path / "results" / "experiments" / "x" / "table.json").write_text(json.dumps({"rows": rows}))
    parts = {"x/runs/a/seeds-0-2": {"device": "GPU (NVIDIA H100 80GB HBM3)"},
             "y/runs/b/seeds-0-4": {"provenance": {"device": "NVIDIA H200"}}}
    for folder, ev in parts.items():
        (tmp_path / "results" / "experiments" / folder).mkdir(parents=True)
        (tmp_path / "results" / "experiments" / folder / "eval.json").write_text(json.dumps(ev))
    ctx = rc.Context(str(tmp_path))
    assert ri._experiment_seeds_gpu(ctx, "x") == "3/5; NVIDIA H100 80GB HBM3, NVIDIA H200"
    assert ri._experiment_seeds_gpu(ctx, "x", run="b") == "5; NVIDIA H200"
    assert ri._experiment_seeds_gpu(ctx, "not-built") == ""


def _named_files(value):
    """The files that results/index.json names: the values of its keys `file` and `*_file`, at any depth."""
    if isinstance(value, dict):
        for key, item in value.items():
            if key == "file" or key.endswith("_file"):
                yield item
            else:
                yield from _named_files(item)
    elif isinstance(value, list):
        for item in value:
            yield from _named_files(item)


def test_every_file_the_index_names_exists():
    """results/index.json (which file makes which row) names only committed files under results/, its tables are
    tables that tools/results_index.py writes, and its eval.py tables pick their columns from COLUMNS."""
    with open(os.path.join(ROOT, "results", "index.json"), encoding="utf-8") as f:
        index = json.load(f)
    files = list(_named_files(index))
    assert len(files) > 100
    assert "headline/ur5e_reach_ppo_eval.json" in files
    assert [f for f in files if not os.path.isfile(os.path.join(ROOT, "results", f))] == []
    assert set(index) - {"about"} <= set(ri.TABLES)
    for name, table in index.items():
        if isinstance(table, dict) and "columns" in table:
            assert set(table["columns"]) <= set(rc.COLUMNS), name
            assert all(set(row) <= {f.name for f in dataclasses.fields(rc.Run)} for row in table["rows"]), name


def test_an_index_row_is_read_from_the_file_it_names():
    """The results index's row for the UR5e reach PPO headline: every cell of ours computed by hand from the JSON
    file that results/index.json names for the row, and the committed results/README.md holds that row."""
    ctx = rc.Context(ROOT)
    row = next(r for r in ctx.index["headline"]["rows"] if r["label"] == "UR5e reach, PPO, 1 cm target")
    assert row["file"] == "headline/ur5e_reach_ppo_eval.json"
    assert row["paper"] == "ur5e-reach-ppo"
    with open(os.path.join(ROOT, "results", row["file"]), encoding="utf-8") as f:
        data = json.load(f)
    ev = data["evaluations"][0]
    reached, self_c = ev["summary"]["target_reached"], ev["summary"]["self_collision"]
    train_config = ev["policy"]["train_config"]
    assert ev["env_name"] == "ur5e-reach"  # no obstacle: the collisions cell is self collisions only
    assert ev["policy"]["env_steps"] >= 0.98 * train_config["num_timesteps"]  # ran its schedule: no --stop-after-steps
    assert data["device"].startswith("GPU (")
    assert data["device"].endswith(")")
    paper = rc.PAPER_ROWS[row["paper"]]
    seeds = {name: [unit["metrics"][name] for unit in ev["units"]] for name in ("target_reached", "self_collision")}
    expected = [
        "Results: UR5e reach, PPO, 1 cm target",
        f"{100 * paper['target_reached']:.1f} % / {100 * paper['self_collision']:.1f} % self",
        f"{100 * reached['mean']:.1f} ± {100 * rc.sample_std(reached):.1f} %{rc.ci(seeds['target_reached'])} / "
        f"{100 * self_c['mean']:.1f} ± {100 * rc.sample_std(self_c):.1f} %{rc.ci(seeds['self_collision'])} self",
        f"{reached['units']}; {data['device'][len('GPU ('):-1]}",
        f"`python train.py {train_config['preset']} --seeds 5`",
        "[ur5e_reach_ppo_eval.json](headline/ur5e_reach_ppo_eval.json)",
    ]
    generated = next(r for r in ri.index_table(ctx) if r[0] == expected[0])
    assert generated == expected
    with open(os.path.join(ROOT, "results", "README.md"), encoding="utf-8") as f:
        assert "\n| " + " | ".join(expected) + " |\n" in f.read()


def test_tables_show_the_sample_std_of_a_population_std():
    """eval.py's `std_units` is the population std over seeds; the tables show the sample std (ddof 1):
    0.0041 over 5 seeds is 0.0041 * sqrt(5 / 4) = 0.004584."""
    assert rc.sample_std({"std_units": 0.0041, "units": 5}) == pytest.approx(0.0045840, abs=1e-7)


def _ttr_report(*walls, preset="ur5e-reach-ppo-plus", target=0.96, first_seed=100, options=()):
    return {"preset": preset, "target": target, "stop_at": 0.975, "train_options": list(options),
            "seeds": [{"seed": first_seed + i, "wall_seconds": w, "reached_target": w < 150} for i, w in enumerate(walls)]}


def test_time_to_result_cell_splits_the_cold_seeds():
    reports = [_ttr_report(169.7, 103.4, 101.4), _ttr_report(113.9, 107.9, first_seed=103)]
    assert rc.time_to_result_cell(reports, [100]) == (
        "101-114 s with the compilation cache (4 seeds), 170 s into an empty one (1 seed); 4 of 5 evaluations at the target")


def test_time_to_result_cell_shows_one_number_where_the_bounds_round_alike():
    assert rc.time_to_result_cell([_ttr_report(101.2, 100.9)], []).startswith(
        "101 s with the compilation cache (2 seeds);")


def test_eval_wall_cell_spans_the_cached_processes():
    report = {"wall_seconds": {"cold": 40.62, "cache": 15.64, "cache2": 15.71}}
    assert rc.eval_wall_cell(report) == "15.6-15.7 s with the compilation cache, 40.6 s into an empty one"


def test_eval_settings_cell_lists_the_further_settings_in_order():
    report = {"field": "obstacle_radius", "settings": [{"wall_seconds": 10.6}, {"wall_seconds": 0.81},
                                                       {"wall_seconds": 4.72}]}
    assert rc.eval_settings_cell(report) == "0.8, 4.7 s per further obstacle_radius (10.6 s the first, loading the checkpoint)"


def test_time_to_result_cell_refuses_reports_of_two_presets():
    with pytest.raises(ValueError, match="differ in preset"):
        rc.time_to_result_cell([_ttr_report(100.0), _ttr_report(100.0, preset="ur5e-reach-ppo")], [])


def test_time_to_result_cell_refuses_reports_of_two_train_options():
    with pytest.raises(ValueError, match="train options"):
        rc.time_to_result_cell([_ttr_report(100.0), _ttr_report(100.0, options=("--algo.num-envs", "16384"))], [])


def test_time_to_result_row_names_the_train_options(tmp_path):
    report = dict(_ttr_report(91.0, options=("--algo.num-envs", "16384")), date="2026-11-30")
    (tmp_path / "results").mkdir()
    (tmp_path / "results" / "ttr.json").write_text(json.dumps(report))
    row = ri._time_to_result_row(rc.Context(str(tmp_path)), {"time_to_result_files": ["ttr.json"], "cache_cold_seeds": []})
    assert "(`ur5e-reach-ppo-plus --algo.num-envs 16384`, training stopped at 97.5 %; 2026-11-30)" in row[0]
