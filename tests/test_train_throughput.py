"""benchmarks/train_throughput.py: the report is written after every round, so a run cut off by a time limit
keeps the rounds it finished (on the point-mass probe)."""

import json
import statistics
import sys
import types

import pytest

from agents import provenance
from benchmarks import train_throughput as tt


def test_the_report_is_written_after_every_round(tmp_path, monkeypatch):
    out = tmp_path / "tp"
    monkeypatch.setattr(sys, "argv", ["train_throughput", "--preset", "point-mass-ppo", "--updates", "1", "--rounds", "3",
                                      "--skip-env-only", "--out", str(out)])
    flags = "--xla_backend_optimization_level=3"  # XLA's default: the report names the flags a run had
    monkeypatch.setenv("XLA_FLAGS", flags)
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
    assert data["meta"]["xla_flags"] == flags
    assert f"XLA_FLAGS: `{flags}`." in out.with_suffix(".md").read_text()
    assert data["meta"]["code"] == provenance.code_version()
    row = data["rows"][0]
    assert row["train_steps_per_s_rounds"] == timed
    assert row["train_steps_per_s"] == pytest.approx(statistics.median(timed))
    assert "2 rounds (of 3 asked) of 1 timed updates" in out.with_suffix(".md").read_text()


def test_several_seed_counts_are_each_a_setting(tmp_path, monkeypatch):
    """--seeds 1 2: one setting per count (seeds vmapped in one program), each timed over all its seeds; the
    per-seed rate is that over the count. Each timed chunk is made to take 0.5 s, so the rates are exact:
    1 update of the probe preset (batch 64 x 8 minibatches of 10-step sequences = 5,120 env steps per seed)
    x seeds / 0.5 s."""
    out = tmp_path / "tp"
    monkeypatch.setattr(sys, "argv", ["train_throughput", "--preset", "point-mass-ppo", "--updates", "1", "--rounds", "1",
                                      "--seeds", "1", "2", "--skip-env-only", "--out", str(out)])
    clock = iter([0.0, 0.5, 10.0, 10.5])  # two timed chunks: start and end of each
    real_time = tt.Training.time

    def timed(self, updates):  # the module's clock (not jax's) reads the hand-made times
        with monkeypatch.context() as m:
            m.setattr(tt, "time", types.SimpleNamespace(perf_counter=lambda: next(clock)))
            return real_time(self, updates)

    monkeypatch.setattr(tt.Training, "time", timed)
    tt.main()
    rows = {r["setting"]: r for r in json.loads(out.with_suffix(".json").read_text())["rows"]}
    assert list(rows) == ["1dev 1 seeds", "1dev 2 seeds"]
    assert [rows[k]["seeds"] for k in rows] == [1, 2]
    assert rows["1dev 1 seeds"]["train_steps_per_s"] == pytest.approx(5120 / 0.5)
    assert rows["1dev 2 seeds"]["train_steps_per_s"] == pytest.approx(2 * 5120 / 0.5)
    assert rows["1dev 2 seeds"]["train_steps_per_s_per_seed"] == pytest.approx(5120 / 0.5)
    # --skip-env-only: the env-only rate and fraction cells are blank, not "nan"
    assert "| 1dev 2 seeds | 1 |  | 64 | 64 | 2 | 5,120 | 20,480 | 10,240 |  |  | 1.00 |" in out.with_suffix(".md").read_text()
    monkeypatch.setattr(sys, "argv", ["train_throughput", "--preset", "point-mass-ppo", "--seeds", "0"])
    with pytest.raises(SystemExit):
        tt.main()
