"""tools/experiment_index.py: results/experiments/README.md names every registered experiment and its commands,
a section's numbers are its table.json's, and the committed README is the generated one (--check)."""

import json

from tools import experiment_index as ei
from tools.experiment_spec import Experiment, Run

FAKE = Experiment("fake", "A fake experiment", 'Table "fake" (tab:fake)',
                  (Run("a", "ur5e-reach-ppo", paper={"target_reached": 0.961}),), paper="The paper's finding.",
                  note="A note on the runs.")

TABLE = {"experiment": "fake", "code": "abc1234", "date": "2026-01-02", "rows": [
    {"run": "a", "label": "row a", "seeds": 3, "seeds_evaluated": 3, "env_steps": 150077440, "eval_envs": 4096,
     "status": "done", "paper": {"target_reached": 0.961},
     "per_seed": {"target_reached": [0.95, 0.96, 0.97], "self_collision": [0.02, 0.03, 0.025],
                  "distance": [0.0185, 0.0205, 0.0200]}},
    {"run": "a", "cross": "b", "label": "row a on b", "seeds": 3, "status": "not evaluated", "paper": {}},
]}


def _out(tmp_path, table=TABLE):
    (tmp_path / "findings.md").write_text("# Findings\n\n## Notes\n\n### `fake`\n\nA finding.\n")
    (tmp_path / "fake").mkdir()
    (tmp_path / "fake" / "table.json").write_text(json.dumps(table))
    return str(tmp_path)


def test_a_section_shows_its_table_json_numbers(tmp_path):
    text = ei.readme(_out(tmp_path), experiments={"fake": FAKE})
    assert text.startswith("# Findings\n")
    # 3 seeds: each extreme mean (all three resamples the same seed) comes up with probability 1/27 > 2.5 %, so the
    # 95 % interval spans the seeds' range.
    assert ("| row a | 3 x 150M | 96.0 ± 1.0 % [95.0, 97.0] (paper 96.1 %) | 2.5 ± 0.5 % [2.0, 3.0] | "
            "0.020 ± 0.001 [0.018, 0.021] |" in text.splitlines())
    assert "| row a on b | not evaluated |  |  |  |" in text.splitlines()
    assert "| run | seeds x env steps | reached | self collision | distance (m) |" in text
    assert "`python -m tools.experiments launch fake`" in text
    assert "`python -m tools.experiments build fake`" in text
    assert "[table.md](fake/table.md)" in text
    assert "[notes](#fake)" in text
    assert "curves.png" not in text  # no figure was built
    assert "built at code abc1234, 2026-01-02" in text
    assert "A note on the runs." in text


def test_an_unbuilt_experiment_says_so(tmp_path):
    out = _out(tmp_path)
    text = ei.readme(out, experiments={"fake": FAKE, "other": Experiment("other", "Other", "not in the paper",
                                                                         (Run("x", "ur5e-reach-ppo"),))})
    assert "### `other`: Other" in text
    assert "Not built yet." in text


def test_every_registered_experiment_and_its_commands_are_named():
    text = ei.readme()
    for name in ei.registered():
        assert f"### `{name}`:" in text
        assert f"`python -m tools.experiments launch {name}`" in text
        assert f"`python -m tools.experiments build {name}`" in text


def test_the_committed_readme_is_up_to_date():
    assert ei.main(["--check"]) == 0, "python -m tools.experiment_index --write"


def test_write_then_check_catches_an_edited_readme(tmp_path, capsys):
    out = _out(tmp_path)
    assert ei.main(["--write", "--out", out]) == 0
    assert ei.main(["--check", "--out", out]) == 0
    with open(tmp_path / "README.md", "a") as f:
        f.write("edited\n")
    assert ei.main(["--check", "--out", out]) == 1
    assert "out of date" in capsys.readouterr().err
