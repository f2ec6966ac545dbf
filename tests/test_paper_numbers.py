"""assets/paper_numbers.json, the one home of the paper's numbers: a few of them hand-copied from the paper
(Weihing and Eivazi, "Learning Reach-Avoid Task with Reinforcement Learning: Vectorized Simulation and
Benchmark"), section or table named beside each; and every `paper` of a registered run or cross-evaluation is a
row of the file, not a number typed into the registry."""

import json

import pytest

from tools import experiment_registry  # noqa: F401  (registers the experiments)
from tools.experiment_spec import EXPERIMENTS, PAPER_NUMBERS, paper_row, paper_table


def test_every_entry_names_its_source_and_fills_its_columns():
    with open(PAPER_NUMBERS, encoding="utf-8") as f:
        data = json.load(f)
    entries = {name: entry for name, entry in data.items() if isinstance(entry, dict)}
    assert len(entries) >= 10
    for name, entry in entries.items():
        assert entry["from"].startswith(("Section", "Table")), name
        assert entry["rows"], name
        assert all(len(row) == len(entry["columns"]) for row in entry["rows"]), name


def test_the_numbers_are_the_papers():
    def pct(entry, **key):
        return {m: round(100 * v, 1) for m, v in paper_row(entry, **key).items()}

    # Section "Results", first paragraph: "96.1% target reached with the UR5e (1 cm target size) and a 2.2%
    # self-collision"; Panda 98.8% with 0.3%; SAC on the UR5e 61.6% (17.3% self-collisions), from the 360° range 84.8%.
    assert pct("reach", run="ur5e-reach-ppo") == {"target_reached": 96.1, "self_collision": 2.2}
    assert pct("reach", run="panda-reach-ppo") == {"target_reached": 98.8, "self_collision": 0.3}
    assert pct("reach", run="ur5e-reach-sac") == {"target_reached": 61.6, "self_collision": 17.3}
    assert pct("reach", run="ur5e-reach-sac-limited-init") == {"target_reached": 84.8, "self_collision": 3.5}
    # Section "Reach-Avoid Task" (Results), second paragraph: UR5e 86.8%, 2.7% self and 4.8% obstacle collisions.
    assert pct("reach_avoid", run="ur5e-reach-avoid-ppo") == {"target_reached": 86.8, "self_collision": 2.7,
                                                             "obstacle_collision": 4.8}
    # Same section, sixth paragraph (Front workspace): Franka 96.1%, 0.1% self, 1.7% obstacle collisions.
    assert pct("reach_avoid_front", robot="panda") == {"target_reached": 96.1, "self_collision": 0.1,
                                                       "obstacle_collision": 1.7}
    # Section "Action space" (Results): 96.5% vs 96.4%, self collisions 3.0% vs 2.3%; Table
    # tab:reaching_actionspace_differences: Position 0.012 ± 0.001, 41.5 ± 3.2, 21.7 ± 0.4.
    absolute = {r["control"]: r for r in paper_table("action_space")}["absolute"]
    assert (absolute["target_reached"], absolute["self_collision"]) == (0.965, 0.030)
    assert [absolute[m] for m in ("distance", "distance_std", "steps_in_target", "steps_in_target_std",
                                  "times_left_target", "times_left_target_std")] == [0.012, 0.001, 41.5, 3.2, 21.7, 0.4]
    # Table tab:reaching_baselines: Pseudo IK, 0.02m: 0.510, 0.222, 0.033m ± 0.035.
    ik = [r for r in paper_table("baselines") if (r["agent"], r["target_radius"]) == ("pseudo_ik", 0.02)]
    assert [ik[0][m] for m in ("target_reached", "self_collision", "distance", "distance_std")] == [0.510, 0.222, 0.033, 0.035]
    # Table tab:reaching_workspace_generalization: Full on Full Range 0.601 ± 0.023, 0.178 ± 0.027, 0.161m ± 0.006.
    ws = [r for r in paper_table("workspace") if (r["trained"], r["evaluated"]) == ("full", "full-range")][0]
    assert [ws[m] for m in ("target_reached", "target_reached_std", "self_collision", "self_collision_std", "distance",
                            "distance_std")] == [0.601, 0.023, 0.178, 0.027, 0.161, 0.006]
    assert len(paper_table("workspace")) == 13
    # Table tab:static_obst_size: reach on 0.3: 0.603 ± 0.006, 0.016 ± 0.002, 0.373 ± 0.006; 0.025 on 0.1: 0.844,
    # 0.038, 0.066.
    assert paper_row("obstacle_size", trained="reach", evaluated=0.3) == {
        "target_reached": 0.603, "self_collision": 0.016, "obstacle_collision": 0.373}
    assert paper_row("obstacle_size", trained="0.025", evaluated=0.1) == {
        "target_reached": 0.844, "self_collision": 0.038, "obstacle_collision": 0.066}
    assert len(paper_table("obstacle_size")) == 14
    # Section "Simulation performance": approximately 185,000 (reach) and around 125,000 (reach-avoid) steps/s.
    assert {r["env"]: r["env_steps_per_second"] for r in paper_table("simulation_performance")} == {
        "ur5e-reach": 185_000, "ur5e-reach-avoid": 125_000}
    with pytest.raises(KeyError, match="has 5 rows"):
        paper_row("obstacle_size", trained="reach")


def _paper_rows() -> list[dict]:
    """Each row of the file reduced to its metrics (a `Run.paper`): the columns that are table metrics."""
    from agents.evaluation import PAPER_METRICS

    with open(PAPER_NUMBERS, encoding="utf-8") as f:
        names = [name for name, entry in json.load(f).items() if isinstance(entry, dict)]
    return [{m: v for m, v in row.items() if m in PAPER_METRICS} for name in names for row in paper_table(name)]


def test_every_registered_paper_number_is_a_row_of_the_file():
    rows = _paper_rows()
    papers = {f"{name}/{r.name}": r.paper for name, exp in EXPERIMENTS.items() for r in exp.runs + exp.cross}
    assert sum(bool(p) for p in papers.values()) >= 49  # every run and cross row that had a literal before
    for where, paper in papers.items():
        assert not paper or paper in rows, f"{where}: {paper} is not a row of {PAPER_NUMBERS}"
    # ... and the right row.
    expected = {
        "action-space/relative": ("action_space", {"control": "relative"}),
        "action-space/absolute": ("action_space", {"control": "absolute"}),
        "relative-step/step-0.6": ("action_space", {"control": "relative"}),
        "reach-observation/paper": ("reach_observation", {"observation": "ee-pos"}),
        "reach-avoid-reward/semi-sparse": ("reach_avoid", {"run": "ur5e-reach-avoid-ppo"}),
        "reach-avoid-observation/no-link-dist": ("reach_avoid_observation", {"observation": "no-link-dist"}),
        "reach-avoid-observation/link-dist": ("reach_avoid_observation", {"observation": "link-dist"}),
        "reach-avoid-front/ur5e-limited": ("reach_avoid_front", {"robot": "ur5e"}),
        "reach-avoid-front/panda": ("reach_avoid_front", {"robot": "panda"}),
        "obstacle-size-ur5e/r0.2": ("obstacle_size", {"trained": "0.2", "evaluated": 0.2}),
        "obstacle-size-ur5e/r0.2-on-0.1": ("obstacle_size", {"trained": "0.2", "evaluated": 0.1}),
        "sac-reach/ur5e-limited-sampled": ("reach", {"run": "ur5e-reach-sac-limited-init"}),
        "sac-fast/panda-reach-avoid": ("reach_avoid", {"run": "panda-reach-avoid-ppo"}),
        "sac-fast/ur5e-reach-sampled": ("reach", {"run": "ur5e-reach-ppo"}),
        "reach-avoid-joint-margin/margin-0.25": ("reach_avoid", {"run": "ur5e-reach-avoid-ppo"}),
    }
    for where, (entry, key) in expected.items():
        assert papers[where] == paper_row(entry, **key), where
