"""tools/compare_runs.py: rliable's aggregates and probability of improvement of fake runs (eval.json files as the
training driver writes them) against hand-computed numbers, its figures, and its refusals of bad input."""

import json
import os

import numpy as np
import pytest

from tools import compare_runs

REPS = 50
"""Few resamples: the tests check estimates and the interval's bracketing, not its width."""
PNG_MAGIC = b"\x89PNG\r\n\x1a\n"

# Algorithm A beats B on every seed of both tasks; A's 8 values sorted: .1 .2 .3 .4 .5 .6 .7 .9.
A = {"reach": [0.1, 0.2, 0.3, 0.4], "avoid": [0.5, 0.6, 0.7, 0.9]}
B = {"reach": [0.0, 0.05, 0.01, 0.02], "avoid": [0.3, 0.2, 0.1, 0.45]}


def write_eval(folder, values: dict) -> str:
    """A train.py logdir holding eval.json as agents/driver.py writes it: {metric: [value per seed]} under
    per_seed (keys with the 'episode/' prefix) and their means."""
    os.makedirs(folder, exist_ok=True)
    per_seed = {f"episode/{k}": v for k, v in values.items()}
    path = os.path.join(folder, "eval.json")
    with open(path, "w") as f:
        json.dump({"env_steps": 1000, "eval_envs": 16, "device": "CPU",
                   "provenance": {"command": "python train.py", "code": "abc1234", "device": "CPU", "date": "2026-01-01"},
                   "per_seed": per_seed, "mean": {k: float(np.mean(v)) for k, v in per_seed.items()}}, f)
    return str(folder)


def run_args(root, scores: dict) -> list[str]:
    """--run arguments for {algo: {task: [values]}}, one logdir each (target_reached and a collision rate)."""
    args = []
    for algo, by_task in scores.items():
        for task, values in by_task.items():
            logdir = write_eval(os.path.join(root, f"{algo}-{task}"),
                                {"target_reached": values, "self_collision": [0.0] * len(values)})
            args += ["--run", f"{algo}:{task}={logdir}"]
    return args


@pytest.fixture(scope="module")
def made(tmp_path_factory):
    """(out folder, comparison.json) of the command on A and B."""
    root = tmp_path_factory.mktemp("runs")
    out = os.path.join(root, "out")
    compare_runs.main(run_args(str(root), {"A": A, "B": B}) + ["--out", out, "--reps", str(REPS)])
    with open(os.path.join(out, "comparison.json")) as f:
        return out, json.load(f)


def test_a_beating_b_on_every_seed_of_every_task_has_probability_one(made):
    assert made[1]["improvement"][0]["estimate"] == 1.0


def test_the_pair_is_a_over_b_in_the_order_given(made):
    assert (made[1]["improvement"][0]["x"], made[1]["improvement"][0]["y"]) == ("A", "B")


def test_iqm_is_the_mean_of_the_middle_half_of_all_runs_and_tasks(made):
    """Of A's 8 values the 2 lowest and 2 highest go: (.3 + .4 + .5 + .6) / 4."""
    assert made[1]["aggregate"]["A"]["IQM"]["estimate"] == pytest.approx(0.45)


def test_mean_is_the_mean_of_task_means(made):
    """Task means .25 and .675."""
    assert made[1]["aggregate"]["A"]["mean"]["estimate"] == pytest.approx(0.4625)


def test_median_of_two_task_means_is_their_middle(made):
    assert made[1]["aggregate"]["A"]["median"]["estimate"] == pytest.approx(0.4625)


def test_optimality_gap_is_the_mean_shortfall_below_one(made):
    assert made[1]["aggregate"]["A"]["optimality gap"]["estimate"] == pytest.approx(1 - 0.4625)


@pytest.mark.parametrize("name", compare_runs.AGGREGATES)
def test_the_interval_holds_the_estimate(made, name):
    stats = made[1]["aggregate"]["B"][name]
    assert stats["ci"][0] <= stats["estimate"] <= stats["ci"][1]


def test_the_interval_of_a_certain_improvement_is_one(made):
    """Every resample of A's seeds still beats every resample of B's."""
    assert made[1]["improvement"][0]["ci"] == [1.0, 1.0]


def test_the_scores_are_the_seeds_values_per_task(made):
    assert made[1]["scores"]["B"]["avoid"] == B["avoid"]


def test_the_markdown_names_the_pair(made):
    with open(os.path.join(made[0], "comparison.md")) as f:
        assert "| A | B | 1.00 [1.00, 1.00] |" in f.read()


@pytest.mark.parametrize("name", ["aggregate.png", "improvement.png"])
def test_the_figures_are_png_images(made, name):
    with open(os.path.join(made[0], name), "rb") as f:
        assert f.read(8) == PNG_MAGIC


@pytest.mark.parametrize("name", ["aggregate.png", "improvement.png"])
def test_the_figures_are_more_than_a_header(made, name):
    assert os.path.getsize(os.path.join(made[0], name)) > 1000


def test_ties_count_half_and_tasks_are_averaged():
    """Task 1: X beats Y on every pair (1); task 2: equal seeds (0.5); the mean over tasks 0.75."""
    x = np.array([[0.9, 0.5], [0.8, 0.5], [0.7, 0.5]])
    y = np.array([[0.1, 0.5], [0.2, 0.5], [0.3, 0.5]])
    assert compare_runs.improvement_estimates({"X": x, "Y": y}, REPS, 0)[0]["estimate"] == pytest.approx(0.75)


def test_a_pair_with_one_loss_in_sixteen_on_one_task():
    """Task 1: 15 of X's 16 pairs with Y win (15/16); task 2: all win (1); the mean 31/32."""
    x = np.array([[0.5, 0.9], [0.6, 0.9], [0.7, 0.9], [0.8, 0.9]])
    y = np.array([[0.1, 0.1], [0.2, 0.1], [0.3, 0.1], [0.55, 0.1]])
    assert compare_runs.improvement_estimates({"X": x, "Y": y}, REPS, 0)[0]["estimate"] == pytest.approx(31 / 32)


def test_the_same_seed_gives_the_same_interval():
    m = {"X": np.array([[0.1, 0.4], [0.5, 0.2], [0.3, 0.9]]), "Y": np.array([[0.2, 0.3], [0.6, 0.1], [0.4, 0.8]])}
    assert compare_runs.aggregate_estimates(m, REPS, 3) == compare_runs.aggregate_estimates(m, REPS, 3)


def test_numpys_global_generator_is_left_as_it_was():
    np.random.seed(7)
    expected = np.random.rand()
    np.random.seed(7)
    compare_runs.aggregate_estimates({"X": np.array([[0.1, 0.4], [0.5, 0.2]])}, REPS, 0)
    assert np.random.rand() == expected


def test_parts_of_a_run_are_read_by_first_seed(tmp_path):
    """seeds-10-10 after seeds-2-2 (numeric, not name order)."""
    for name, values in (("seeds-0-1", [0.1, 0.2]), ("seeds-10-10", [0.4]), ("seeds-2-2", [0.3])):
        write_eval(tmp_path / name, {"target_reached": values})
    scores, _ = compare_runs.collect([("A", "reach", str(tmp_path))], "target_reached")
    assert scores["A"]["reach"] == [0.1, 0.2, 0.3, 0.4]


def test_the_same_algorithm_and_task_again_adds_seeds(tmp_path):
    first = write_eval(tmp_path / "a", {"target_reached": [0.1]})
    second = write_eval(tmp_path / "b", {"target_reached": [0.2]})
    scores, _ = compare_runs.collect([("A", "reach", first), ("A", "reach", second)], "target_reached")
    assert scores["A"]["reach"] == [0.1, 0.2]


def test_an_eval_json_path_is_read_as_its_logdir(tmp_path):
    logdir = write_eval(tmp_path / "a", {"target_reached": [0.7]})
    scores, _ = compare_runs.collect([("A", "reach", os.path.join(logdir, "eval.json"))], "target_reached")
    assert scores["A"]["reach"] == [0.7]


def test_the_metric_may_carry_its_prefix(tmp_path):
    logdir = write_eval(tmp_path / "a", {"target_reached": [0.7]})
    scores, _ = compare_runs.collect([("A", "reach", logdir)], "episode/target_reached")
    assert scores["A"]["reach"] == [0.7]


def test_an_unknown_metric_is_refused_naming_it_and_the_allowed(tmp_path):
    logdir = write_eval(tmp_path / "a", {"target_reached": [0.7]})
    with pytest.raises(ValueError, match=r"'nonsense'.*allowed are target_reached"):
        compare_runs.main(["--run", f"A:reach={logdir}", "--metric", "nonsense", "--out", str(tmp_path / "o")])


def test_a_path_without_eval_json_is_refused_naming_it(tmp_path):
    empty = tmp_path / "empty"
    empty.mkdir()
    with pytest.raises(ValueError, match="empty' has no eval.json"):
        compare_runs.main(["--run", f"A:reach={empty}", "--out", str(tmp_path / "o")])


@pytest.mark.parametrize("text", ["A=runs/x", "A:=runs/x", ":reach=runs/x", "A:reach", "A,B:reach=runs/x"])
def test_a_malformed_run_is_refused_naming_it(text):
    with pytest.raises(ValueError, match=f"--run '{text}' is malformed"):
        compare_runs.parse_run(text)


def test_a_run_is_split_into_algorithm_task_and_path():
    assert compare_runs.parse_run("fast SAC:ur5e-reach=runs/a=b") == ("fast SAC", "ur5e-reach", "runs/a=b")


def test_the_same_file_twice_is_refused(tmp_path):
    logdir = write_eval(tmp_path / "a", {"target_reached": [0.7]})
    with pytest.raises(ValueError, match="given twice"):
        compare_runs.collect([("A", "reach", logdir), ("B", "reach", logdir)], "target_reached")


def test_a_nan_seed_is_refused_naming_the_metric(tmp_path):
    logdir = write_eval(tmp_path / "a", {"target_reached": [0.7, float("nan")]})
    with pytest.raises(ValueError, match="episode/target_reached is"):
        compare_runs.collect([("A", "reach", logdir)], "target_reached")


def test_unequal_seeds_across_an_algorithms_tasks_are_refused():
    scores = {"A": {"reach": [0.1, 0.2, 0.3], "avoid": [0.4, 0.5]}, "B": {"reach": [0.1], "avoid": [0.2]}}
    with pytest.raises(ValueError, match=r"'A' has unequal seeds per task \(reach 3, avoid 2\)"):
        compare_runs.score_matrices(scores)


def test_truncation_keeps_each_tasks_first_seeds():
    scores = {"A": {"reach": [0.1, 0.2, 0.3], "avoid": [0.4, 0.5]}, "B": {"reach": [0.1], "avoid": [0.2]}}
    with pytest.warns(UserWarning, match="first 2 kept"):
        matrices, _, _ = compare_runs.score_matrices(scores, truncate=True)
    assert matrices["A"].tolist() == [[0.1, 0.4], [0.2, 0.5]]


def test_truncation_records_the_seeds_left_out():
    scores = {"A": {"reach": [0.1, 0.2, 0.3], "avoid": [0.4, 0.5]}, "B": {"reach": [0.1], "avoid": [0.2]}}
    with pytest.warns(UserWarning):
        _, _, dropped = compare_runs.score_matrices(scores, truncate=True)
    assert dropped == {"A": {"reach": 1}}


def test_algorithms_may_differ_in_seeds():
    scores = {"A": {"reach": [0.1, 0.2, 0.3]}, "B": {"reach": [0.1]}}
    assert compare_runs.score_matrices(scores)[0]["B"].shape == (1, 1)


def test_a_missing_task_is_refused_naming_it():
    with pytest.raises(ValueError, match=r"'B' has no run for task\(s\) avoid"):
        compare_runs.score_matrices({"A": {"reach": [0.1], "avoid": [0.2]}, "B": {"reach": [0.1]}})


def test_one_algorithm_is_refused():
    with pytest.raises(ValueError, match=r"1 algorithm\(s\) \(A\): allowed are 2 or more"):
        compare_runs.score_matrices({"A": {"reach": [0.1]}})


def test_non_positive_reps_are_refused(tmp_path):
    with pytest.raises(ValueError, match="--reps 0"):
        compare_runs.compare([], "target_reached", str(tmp_path), reps=0)


@pytest.mark.parametrize("key", ["command", "code", "device", "date"])
def test_the_json_names_what_made_it(made, key):
    assert made[1]["provenance"][key]


def test_a_negative_seed_is_refused(tmp_path):
    with pytest.raises(ValueError, match="--seed -1"):
        compare_runs.compare([], "target_reached", str(tmp_path), seed=-1)
