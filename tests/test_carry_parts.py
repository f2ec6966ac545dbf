"""tools.carry_parts: an unfinished part moves to another runs folder learner-only and resumes there."""

import csv
import json
import os

import jax
import numpy as np
import pytest

from agents import driver, presets
from agents.checkpoint import Checkpointer
from tools import carry_parts

SHORT = 30_720  # 6 updates of the PPO probe preset (the program tests/test_loop_train.py compiles)
BASE = dict(num_timesteps=SHORT, eval_envs=0, log_every=5120, tensorboard=False, progress=False)


def _stored_leaf_names(step_dir: str) -> list[str]:
    with open(os.path.join(step_dir, "state", "_METADATA")) as f:
        return list(json.load(f)["tree_metadata"])


def test_an_unfinished_part_is_packed_learner_only_in_pieces_and_resumes_after_unpacking(tmp_path):
    runs, carry, there = tmp_path / "runs", str(tmp_path / "carry"), str(tmp_path / "there")
    part = str(runs / "toy" / "b" / "seeds-0-0")
    first = driver.train(presets.make_config("point-mass-ppo", logdir=part, stop_after_steps=15_360, **BASE))
    assert first.status == "stopped"
    assert any("env_state" in n for n in _stored_leaf_names(os.path.join(part, "checkpoints", "15360")))
    done = runs / "toy" / "b" / "seeds-1-1"  # evaluated: done, not packed
    os.makedirs(done / "checkpoints" / "30720")
    (done / "eval.json").write_text("{}")
    os.makedirs(runs / "toy" / "b" / "seeds-2-2")  # nothing trained yet: not packed
    assert carry_parts.unfinished_parts(str(runs)) == ["toy/b/seeds-0-0"]

    pieces = carry_parts.pack(str(runs), carry, max_mb=0.05, log=lambda s: None)
    assert len(pieces) > 1 and all(os.path.getsize(p) <= 0.05 * 2**20 for p in pieces)
    assert [os.path.basename(p) for p in pieces][:2] == ["parts.tgz.000", "parts.tgz.001"]

    assert carry_parts.unpack(carry, there, log=lambda s: None) == ["toy/b/seeds-0-0"]
    moved = os.path.join(there, "toy", "b", "seeds-0-0")
    assert sorted(os.listdir(os.path.join(moved, "checkpoints"))) == ["15360"]
    stored = _stored_leaf_names(os.path.join(moved, "checkpoints", "15360"))
    assert any("learner" in n for n in stored) and not any("env_state" in n for n in stored)
    with open(os.path.join(moved, "metrics.csv")) as f:
        assert [int(float(r["env_steps"])) for r in csv.DictReader(f)] == [5120, 10240, 15360]
    ckpt = Checkpointer(os.path.join(moved, "checkpoints"))
    programs = driver.programs_for(first.config)
    saved = driver.restore_state(ckpt, 15_360, programs, first.config, with_envs=False)
    ckpt.close()
    for a, b in zip(jax.tree.leaves(jax.device_get(first.state.learner)), jax.tree.leaves(jax.device_get(saved.learner))):
        np.testing.assert_array_equal(np.asarray(a), np.asarray(b))  # the learner arrives exactly

    resumed = driver.train(presets.make_config("point-mass-ppo", logdir=moved, resume=True, **BASE))
    assert resumed.status == "done" and resumed.env_steps == SHORT
    # Unpacked again, the part keeps its newer checkpoint here.
    assert carry_parts.unpack(carry, there, log=lambda s: None) == []
    assert str(SHORT) in os.listdir(os.path.join(moved, "checkpoints"))


def test_bad_arguments_are_refused_naming_the_option(tmp_path):
    with pytest.raises(ValueError, match="pack needs --to"):
        carry_parts.main(["pack", "--runs-dir", str(tmp_path)])
    with pytest.raises(ValueError, match="unpack needs --from"):
        carry_parts.main(["unpack"])
    with pytest.raises(ValueError, match="--from=.* holds no parts.tgz"):
        carry_parts.main(["unpack", "--from", str(tmp_path)])
    with pytest.raises(ValueError, match="max_mb=0.0 is invalid"):
        carry_parts.pack(str(tmp_path), str(tmp_path / "out"), max_mb=0.0)
    assert carry_parts.pack(str(tmp_path), str(tmp_path / "out"), log=lambda s: None) == []


def test_a_part_without_an_intact_checkpoint_is_refused_naming_the_logdir(tmp_path):
    os.makedirs(tmp_path / "part" / "checkpoints")
    with pytest.raises(ValueError, match=r"logdir=.*part' holds no intact checkpoint \(none found\)"):
        driver.learner_only_checkpoint(str(tmp_path / "part"), str(tmp_path / "dest"))
