"""tools/failure_report.py's picture: drawn from a report written earlier (`--from-json`), with the command line's
checks."""

import json

import pytest

from tools import failure_report

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
])
def test_command_line_refuses_incomplete_input(argv, named):
    with pytest.raises(ValueError, match=named):
        failure_report.main(argv)
