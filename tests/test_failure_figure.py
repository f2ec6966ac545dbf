"""tools/failure_report.py's picture: drawn from a report written earlier (`--from-json`), with the command line's
checks, and its `--env.<field>` options."""

import json
import os

import pytest

import envs
from agents import evaluation
from tools import failure_report

SHIPPED = os.path.join(os.path.dirname(os.path.dirname(os.path.abspath(__file__))), "results", "checkpoints",
                       "ur5e-reach-ppo")

SUMMARY = {"episodes": 4, "outcomes": {"reached": 0.5, "self collision": 0.25, "missed": 0.25},
           "collisions": {"by_part": {"self collision: forearm_b / wrist_3": 1}},
           "by_target_height": {"< 0 cm": {"episodes": 2, "reached": 1.0},
                                "> 50 cm": {"episodes": 2, "self collision": 0.5, "missed": 0.5}}}


def test_figure_draws_one_bar_per_outcome_and_colliding_part(tmp_path):
    fig = failure_report.figure(SUMMARY, "hand-made", str(tmp_path / "r.png"))
    outcomes, parts, heights = fig.axes
    assert [round(p.get_height(), 6) for p in outcomes.patches] == [50.0, 25.0, 25.0]
    assert [p.get_width() for p in parts.patches] == [1]
    assert [t.get_text() for t in parts.get_yticklabels()] == ["forearm_b / wrist_3"]
    assert (tmp_path / "r.png").read_bytes()[:4] == b"\x89PNG"


def test_figure_stacks_the_outcomes_of_each_target_height_to_100(tmp_path):
    fig = failure_report.figure(SUMMARY, "hand-made")
    tops = {}
    for p in fig.axes[2].patches:
        tops[round(p.get_x(), 3)] = max(tops.get(round(p.get_x(), 3), 0), p.get_y() + p.get_height())
    assert sorted(round(v, 6) for v in tops.values()) == [100.0, 100.0]


def test_command_line_draws_a_saved_report(tmp_path):
    report = tmp_path / "report.json"
    report.write_text(json.dumps({"summary": SUMMARY, "note": "hand-made"}))
    failure_report.main(["--from-json", str(report), "--plot", str(tmp_path / "r.png")])
    assert (tmp_path / "r.png").stat().st_size > 1000


@pytest.mark.parametrize("argv, named", [
    ([], "give exactly one of --checkpoint PATH"),
    (["--from-json", "r.json"], "--from-json needs --plot PNG"),
    (["--from-json", "r.json", "--plot", "r.png", "--env.substeps", "2"],
     "'--env.substeps' is invalid with --from-json"),
    (["--from-json", "r.json", "--plot", "r.png", "--samples", "2"], "option '--samples' is unknown"),
])
def test_command_line_refuses_incomplete_input(argv, named):
    with pytest.raises(ValueError, match=named):
        failure_report.main(argv)


def test_env_options_replace_the_checkpoints_fields():
    base = envs.make_config("ur5e-reach-avoid", obstacle_motion="linear")
    config = failure_report.env_options(base, ["--env.obstacle-speed-range", "0", "0.01", "--env.substeps", "4",
                                               "--env.collision-penalty", "-1"])
    assert config.obstacle_speed_range == (0.0, 0.01)
    assert config.substeps == 4
    assert config.collision_penalty == -1.0  # a negative value is a value, not an option
    assert config.obstacle_motion == "linear"  # the rest kept


@pytest.mark.parametrize("argv", [["--samples", "4"], ["0.5", "--env.substeps", "4"]])
def test_an_option_other_than_env_fields_is_refused_naming_it(argv):
    with pytest.raises(ValueError, match=f"option {argv[0]!r} is unknown"):
        failure_report.env_options(envs.make_config("ur5e-reach-avoid"), argv)


def test_an_impossible_env_value_is_refused_naming_the_field_before_any_episode(monkeypatch):
    monkeypatch.setattr(failure_report, "classify", lambda *a, **k: pytest.fail("episodes were run"))
    with pytest.raises(ValueError, match=r"substeps=0 is invalid: allowed is an integer >= 1"):
        failure_report.main(["--checkpoint", SHIPPED, "--num-envs", "1", "--env.substeps", "0"])


def test_the_episodes_run_on_the_replaced_fields_with_the_mismatch_allowance(monkeypatch):
    seen = {}
    monkeypatch.setattr(evaluation, "rollout",
                        lambda policy, name, config, **options: seen.update(config=config, **options))
    monkeypatch.setattr(failure_report, "classify", lambda *a, **k: [])
    monkeypatch.setattr(failure_report, "summarize", lambda rows, near_limit=None: {"episodes": 0})
    monkeypatch.setattr(failure_report, "markdown", lambda summary, title: title)
    failure_report.main(["--checkpoint", SHIPPED, "--num-envs", "1", "--env.substeps", "4", "--allow-env-mismatch"])
    assert seen["config"].substeps == 4
    assert seen["allow_env_mismatch"] is True


def test_an_env_the_policy_cannot_run_in_is_refused_before_any_episode(monkeypatch):
    monkeypatch.setattr(failure_report, "classify", lambda *a, **k: pytest.fail("episodes were run"))
    with pytest.raises(ValueError, match=r"cannot run with action='absolute' \(trained: 'relative'\)"):
        failure_report.main(["--checkpoint", SHIPPED, "--num-envs", "1", "--env.action", "absolute"])
