"""tools/readme_media.py: the headline figure's numbers against the results files read directly, and the animation's
joining of clips of unequal length (the rendering itself is eval.py --video's, tested in test_eval.py)."""

import json
import os

import numpy as np

from tools import readme_media
from tools.results_cells import Context

RESULTS = os.path.join(readme_media.ROOT, "results")


def _rows():
    return readme_media.headline_rows(Context(readme_media.ROOT))


def test_headline_rows_are_the_papers_four_ppo_rows_and_its_sac_row():
    assert [r["label"].split(",")[:2] for r in _rows()] == [
        ["UR5e reach", " PPO"], ["Panda reach", " PPO"], ["UR5e reach-avoid", " PPO"], ["Panda reach-avoid", " PPO"],
        ["UR5e reach", " SAC"]]


def test_headline_paper_rate_is_the_papers_number():
    assert _rows()[0]["paper"] == 0.961  # "96.1 % target reached with the UR5e", section Reach Task


def test_headline_preset_rates_are_the_per_seed_rates_of_the_eval_file():
    with open(os.path.join(RESULTS, "headline", "panda_reach_ppo_eval.json")) as f:
        units = json.load(f)["evaluations"][0]["units"]
    assert _rows()[1]["preset"] == [u["metrics"]["target_reached"] for u in units]


def test_headline_paper_settings_rates_are_the_seed_runs_of_the_paper_preset():
    folder = os.path.join(RESULTS, "fidelity", "paper_presets", "ur5e-reach-ppo-paper")
    seeds = sorted(d for d in os.listdir(folder) if d.startswith("seed"))
    expected = [json.load(open(os.path.join(folder, s, "eval.json")))["mean"]["episode/target_reached"] for s in seeds]
    assert _rows()[0]["paper_settings"] == expected


def test_headline_figure_writes_a_png(tmp_path):
    out = tmp_path / "headline.png"
    readme_media.headline_figure(_rows(), str(out))
    assert out.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"


def test_side_by_side_holds_the_last_frame_of_the_shorter_clip():
    short = np.zeros((2, 1, 1, 3), np.uint8)
    short[1] = 7
    long = np.full((4, 1, 2, 3), 9, np.uint8)
    joined = readme_media.side_by_side([short, long])
    assert joined.shape == (4, 1, 3, 3)
    assert joined[3, 0, 0, 0] == 7  # the shorter clip's last frame, held
    assert joined[3, 0, 2, 0] == 9
