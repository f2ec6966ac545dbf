"""benchmarks/train_throughput.py: the report is written after every round, so a run cut off by a time limit
keeps the rounds it finished (on the point-mass probe)."""

import json
import statistics
import sys

import pytest

from benchmarks import train_throughput as tt


def test_the_report_is_written_after_every_round(tmp_path, monkeypatch):
    out = tmp_path / "tp"
    monkeypatch.setattr(sys, "argv", ["train_throughput", "--preset", "point-mass-ppo", "--updates", "1", "--rounds", "3",
                                      "--skip-env-only", "--out", str(out)])
    timed, real = [], tt.Training.time

    def time_until_the_limit(self, updates):
        if len(timed) == 2:
            raise KeyboardInterrupt  # the call's time limit, in round 3
        timed.append(real(self, updates))
        return timed[-1]

    monkeypatch.setattr(tt.Training, "time", time_until_the_limit)
    with pytest.raises(KeyboardInterrupt):
        tt.main()
    data = json.loads(out.with_suffix(".json").read_text())
    assert (data["meta"]["rounds"], data["meta"]["rounds_asked"]) == (2, 3)
    row = data["rows"][0]
    assert row["train_steps_per_s_rounds"] == timed and row["train_steps_per_s"] == pytest.approx(statistics.median(timed))
    assert "2 rounds (of 3 asked) of 1 timed updates" in out.with_suffix(".md").read_text()
