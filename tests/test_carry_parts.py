"""tools.carry_parts: unfinished parts move to another runs folder learner-only and resume there; a damaged part
or a lost piece costs only its own part; a done part, a newer one or another config here is kept."""

import json
import os
import re
import shutil

import jax
import numpy as np
import pytest

from agents import driver
from agents.checkpoint import Checkpointer
from tools import carry_parts
from tools import experiments as ex

QUIET = dict(tensorboard=False, progress=False)
# The configs of tests/test_loop_train.py's exact-resume and learner-only SAC tests: the same compiled programs.
PPO_RUN = ex.Run("ppo", "point-mass-ppo", dict(eval_envs=0, log_every=5120, checkpoint_every=5120, **QUIET), seeds=1,
                 num_timesteps=30_720)
SAC_RUN = ex.Run("sac", "point-mass-sac", dict(eval_envs=0, log_every=1_600, checkpoint_envs=False, **QUIET), seeds=1,
                 num_timesteps=3_200)
EXP = ex.Experiment("toy", "carried parts", "not in the paper", (PPO_RUN, SAC_RUN), metrics=("target_reached",))
REGISTRY = {"toy": EXP}


def _stored_leaf_names(step_dir: str) -> list[str]:
    with open(os.path.join(step_dir, "state", "_METADATA")) as f:
        return list(json.load(f)["tree_metadata"])


def _learner_of(part_dir: str, step: int, config):
    ckpt = Checkpointer(os.path.join(part_dir, "checkpoints"))
    try:
        return driver.restore_state(ckpt, step, driver.programs_for(config), config, with_envs=False).learner
    finally:
        ckpt.close()


def _assert_same_tree(a, b):
    for x, y in zip(jax.tree.leaves(jax.device_get(a)), jax.tree.leaves(jax.device_get(b)), strict=True):
        np.testing.assert_array_equal(np.asarray(x), np.asarray(y))


@pytest.fixture(scope="module")
def runs(tmp_path_factory):
    """A runs folder with a PPO part stopped half way (full checkpoints), a SAC part stopped half way
    (learner-only checkpoints), a PPO part whose newest checkpoint is damaged, one whose every checkpoint is,
    a done part and a part never trained; and the stopped runs' results."""
    root = tmp_path_factory.mktemp("carry")
    runs = str(root / "runs")
    part = lambda run, first=0: os.path.join(runs, "toy", run.name, ex.part_name(first, 1))
    ppo = driver.train(PPO_RUN.config(part(PPO_RUN), stop_after_steps=15_360))
    sac = driver.train(SAC_RUN.config(part(SAC_RUN), stop_after_steps=1_600))
    assert ppo.status == sac.status == "stopped"
    for first, damage in ((1, ["15360"]), (2, ["5120", "10240", "15360"])):
        shutil.copytree(part(PPO_RUN), part(PPO_RUN, first))
        for step in damage:  # the config's metadata truncated, as tests/test_run_safety.py damages one
            meta = os.path.join(part(PPO_RUN, first), "checkpoints", step, "config", "metadata")
            with open(meta) as f:
                text = f.read()
            with open(meta, "w") as f:
                f.write(text[:10])
    os.makedirs(os.path.join(part(SAC_RUN, 1), "checkpoints", "3200"))
    with open(os.path.join(part(SAC_RUN, 1), "eval.json"), "w") as f:
        f.write("{}")
    os.makedirs(part(SAC_RUN, 2))
    return root, runs, ppo, sac


def test_unfinished_parts_are_packed_learner_only_and_resume_after_unpacking(runs):
    root, runs_dir, ppo, sac = runs
    assert carry_parts.unfinished_parts(runs_dir) == ["toy/ppo/seeds-0-0", "toy/ppo/seeds-1-1", "toy/ppo/seeds-2-2",
                                                      "toy/sac/seeds-0-0"]
    source = os.path.join(runs_dir, "toy/ppo/seeds-0-0/checkpoints/15360")
    assert any("env_state" in n for n in _stored_leaf_names(source))
    lines, carry, there = [], str(root / "carry"), str(root / "there")
    pieces = carry_parts.pack(runs_dir, carry, max_mb=0.05, max_files=100, log=lines.append)
    assert any(line.startswith("left out toy/ppo/seeds-2-2: ValueError") for line in lines), lines
    names = [os.path.basename(p) for p in pieces]
    assert {n.rsplit(".", 1)[0] for n in names} == {"toy__ppo__seeds-0-0.tgz", "toy__ppo__seeds-1-1.tgz",
                                                    "toy__sac__seeds-0-0.tgz"}
    assert "toy__ppo__seeds-0-0.tgz.001" in names  # split into pieces of at most 0.05 MiB
    assert all(os.path.getsize(p) <= 0.05 * 2**20 for p in pieces)

    assert carry_parts.unpack(carry, there, log=lambda s: None) == ["toy/ppo/seeds-0-0", "toy/ppo/seeds-1-1",
                                                                    "toy/sac/seeds-0-0"]
    moved = {rel: os.path.join(there, rel) for rel in ("toy/ppo/seeds-0-0", "toy/ppo/seeds-1-1", "toy/sac/seeds-0-0")}
    assert os.listdir(os.path.join(moved["toy/ppo/seeds-0-0"], "checkpoints")) == ["15360"]
    assert os.listdir(os.path.join(moved["toy/ppo/seeds-1-1"], "checkpoints")) == ["10240"]  # the newest intact one
    stored = _stored_leaf_names(os.path.join(moved["toy/ppo/seeds-0-0"], "checkpoints", "15360"))
    assert any("learner" in n for n in stored) and not any("env_state" in n for n in stored)
    _assert_same_tree(ppo.state.learner, _learner_of(moved["toy/ppo/seeds-0-0"], 15_360, ppo.config))
    sac_learner = _learner_of(moved["toy/sac/seeds-0-0"], 1_600, sac.config)
    for name in ("policy_params", "q_params", "target_q_params", "log_alpha", "q_opt", "obs_stats"):
        _assert_same_tree(getattr(sac.state.learner, name), getattr(sac_learner, name))
    # The experiments runner reads the carried parts as partly trained, under the registry's config.
    states = {run.name: ex.run_state(EXP, run, there, registry=REGISTRY) for run in EXP.runs}
    assert [(p.name, p.status, p.steps) for p in states["ppo"].parts][:1] == [("seeds-0-0", "partial", 15_360)]
    assert [(p.name, p.status, p.steps) for p in states["sac"].parts] == [("seeds-0-0", "partial", 1_600)]
    resumed = driver.train(PPO_RUN.config(moved["toy/ppo/seeds-0-0"], resume=True))
    assert resumed.status == "done" and resumed.env_steps == 30_720
    # Unpacked again: the resumed part keeps its newer checkpoint here.
    lines.clear()
    assert "toy/ppo/seeds-0-0" not in carry_parts.unpack(carry, there, log=lines.append)
    assert "kept toy/ppo/seeds-0-0: it has a checkpoint at 30,720 env steps here (packed: 15,360)" in lines


def test_unpack_skips_a_part_with_a_lost_piece_and_keeps_done_or_other_parts_here_and_pack_bundles(runs):
    root, runs_dir, _, _ = runs
    carry, there = str(root / "carry2"), str(root / "there2")
    carry_parts.pack(runs_dir, carry, max_mb=0.05, max_files=100, log=lambda s: None)
    os.remove(os.path.join(carry, "toy__ppo__seeds-0-0.tgz.001"))
    done = os.path.join(there, "toy", "sac", "seeds-0-0")  # done here, with no checkpoint left
    os.makedirs(done)
    with open(os.path.join(done, "eval.json"), "w") as f:
        f.write("{}")
    other = os.path.join(there, "toy", "ppo", "seeds-1-1")  # an older checkpoint of another config
    os.makedirs(os.path.join(other, "checkpoints", "5120"))
    stored = json.load(open(os.path.join(runs_dir, "toy", "ppo", "seeds-1-1", "config.json")))
    with open(os.path.join(other, "config.json"), "w") as f:
        json.dump({**stored, "seed": 99}, f)
    lines = []
    assert carry_parts.unpack(carry, there, log=lines.append) == []
    assert "skipped toy__ppo__seeds-0-0.tgz: ValueError: piece 001 is missing" in lines
    assert "kept toy/sac/seeds-0-0: it is done here (eval.json)" in lines
    assert "kept toy/ppo/seeds-1-1: its config.json here differs from the packed one" in lines
    assert os.listdir(done) == ["eval.json"] and json.load(open(os.path.join(other, "config.json")))["seed"] == 99
    # One bundle holds all three when they fit, and only the first bundle is read by an unpack.
    pieces = carry_parts.pack(runs_dir, carry, max_total_mb=1.0, log=lambda s: None)
    assert {os.path.dirname(p) for p in pieces} == {carry}
    os.makedirs(os.path.join(carry, "more-1"))
    shutil.copy(pieces[0], os.path.join(carry, "more-1", "toy__other__seeds-0-0.tgz.000"))
    assert carry_parts.unpack(carry, str(root / "there3"), log=lambda s: None) == [
        "toy/ppo/seeds-0-0", "toy/ppo/seeds-1-1", "toy/sac/seeds-0-0"]


def test_pack_fills_bundles_first_fit_within_what_a_call_brings_back(tmp_path, monkeypatch):
    """Archives of fixed sizes (MiB) in place of the learner-only saves: the parts with the most steps first,
    each into the first bundle with room (a small late part back-fills the first bundle), a part larger than a
    bundle left out, and the pieces kept within the files and MiB a device call brings back; a second pack
    replaces the first one's bundles and removes a bundle folder left empty."""
    mib = {"big": 0.9, "mid": 0.6, "small": 0.3, "huge": 1.5, "tail": 0.5}
    steps = {"big": 500, "mid": 400, "huge": 300, "small": 200, "tail": 100}
    runs_dir = tmp_path / "runs"
    for name, step in steps.items():
        os.makedirs(runs_dir / "toy" / name / "seeds-0-0" / "checkpoints" / str(step))
    monkeypatch.setattr(carry_parts, "_part_archive", lambda runs, rel, staging: (
        b"x" * int(mib[rel.split(os.sep)[1]] * 2**20), steps[rel.split(os.sep)[1]]))
    to, lines = str(tmp_path / "carry"), []

    def bundles():
        return {os.path.relpath(root, to): sorted(f.split("__")[1] for f in files if f.endswith(".000"))
                for root, _, files in os.walk(to) if files}

    pieces = carry_parts.pack(str(runs_dir), to, max_mb=0.5, max_total_mb=1.2, max_files=5, max_all_mb=10,
                              log=lines.append)
    # big (2 pieces) opens "."; mid does not fit beside it: more-1; huge is larger than a bundle; small back-fills
    # "."; tail would fit in more-1 but its piece would be the 6th file
    assert bundles() == {".": ["big", "small"], "more-1": ["mid"]}
    assert len(pieces) == 5 and all(os.path.getsize(p) <= 0.5 * 2**20 for p in pieces)
    assert any(line.startswith("left out toy/huge/seeds-0-0 at 300 env steps: 1.50 MiB is more than --max-total-mb")
               for line in lines), lines
    assert any(line.startswith("left out toy/tail/seeds-0-0 at 100 env steps: with its 1 piece(s), 0.5 MiB, the "
                               "bundles would pass what a device call brings back (5 files, 10 MiB)") for line in lines)
    assert lines[-1].startswith("5 piece(s), 1.8 MiB, in 2 bundle(s):"), lines[-1]
    # Within 1.4 MiB in all: mid (to 1.5) and tail are left out
    carry_parts.pack(str(runs_dir), to, max_mb=0.5, max_total_mb=1.2, max_all_mb=1.4, log=lambda s: None)
    assert bundles() == {".": ["big", "small"]}
    assert not os.path.exists(os.path.join(to, "more-1"))  # emptied by the new pack and removed
    with open(os.path.join(to, "more-5"), "w") as f:  # a file of a bundle's name is left alone
        f.write("not a bundle")
    carry_parts.pack(str(runs_dir), to, max_mb=0.5, max_total_mb=1.2, log=lambda s: None)
    assert bundles()["."] == ["big", "small"] and bundles()["more-1"] == ["mid", "tail"]


def test_pack_takes_only_the_named_runs_parts(tmp_path, monkeypatch):
    """Two commands may train different runs in one runs folder side by side: each packs only its own runs'
    unfinished parts (`runs`, or the CLI's names resolved to the folders that train them)."""
    runs_dir = tmp_path / "runs"
    steps = {"sac-fast/panda-reach-plus-200m/seeds-2-2": 56, "sac-fast/panda-reach-avoid-plus-200m/seeds-3-3": 168,
             "sac-fast/panda-reach-avoid-plus-200m/seeds-4-4": 12, "action-space/relative/seeds-0-0": 7}
    for rel, step in steps.items():
        os.makedirs(runs_dir / rel / "checkpoints" / str(step))
    monkeypatch.setattr(carry_parts, "_part_archive", lambda runs, rel, staging: (b"x" * 1000, steps[rel]))
    to = str(tmp_path / "carry")

    def packed():
        return sorted(os.path.basename(p) for p in os.listdir(to) if p.endswith(".000"))

    carry_parts.pack(str(runs_dir), to, runs=["sac-fast/panda-reach-avoid-plus-200m"], log=lambda s: None)
    assert packed() == ["sac-fast__panda-reach-avoid-plus-200m__seeds-3-3.tgz.000",
                        "sac-fast__panda-reach-avoid-plus-200m__seeds-4-4.tgz.000"]
    # A part whose lock is held (a command training it) is left out, named.
    with ex.part_lock(str(runs_dir / "sac-fast/panda-reach-avoid-plus-200m/seeds-4-4")) as held:
        assert held is None
        lines = []
        carry_parts.pack(str(runs_dir), to, runs=["sac-fast/panda-reach-avoid-plus-200m"], log=lines.append)
    assert packed() == ["sac-fast__panda-reach-avoid-plus-200m__seeds-3-3.tgz.000"]
    assert any(line.startswith("left out sac-fast/panda-reach-avoid-plus-200m/seeds-4-4: another process (pid ")
               for line in lines), lines
    lines = []
    assert carry_parts.pack(str(runs_dir), to, runs=["sac-fast/panda-reach"], log=lines.append) == []  # no prefix match
    assert lines == [f"no unfinished part under {runs_dir} in sac-fast/panda-reach"]
    carry_parts.main(["pack", "--runs-dir", str(runs_dir), "--to", to, "sac-fast/panda-reach-plus-200m",
                      "sac-fast/ur5e-reach-ppo"])  # the PPO row trains in action-space/relative
    assert packed() == ["action-space__relative__seeds-0-0.tgz.000",
                        "sac-fast__panda-reach-plus-200m__seeds-2-2.tgz.000"]
    carry_parts.main(["pack", "--runs-dir", str(runs_dir), "--to", to])
    assert len(packed()) == 4
    with pytest.raises(ValueError, match="unpack needs --from DIR \\(and no names"):
        carry_parts.main(["unpack", "--from", to, "sac-fast"])
    with pytest.raises(ValueError, match="experiment 'nope' is unknown"):
        carry_parts.main(["pack", "--runs-dir", str(runs_dir), "--to", to, "nope"])


def test_bad_arguments_are_refused_naming_the_option(tmp_path):
    with pytest.raises(ValueError, match="pack needs --to"):
        carry_parts.main(["pack", "--runs-dir", str(tmp_path)])
    with pytest.raises(ValueError, match="unpack needs --from"):
        carry_parts.main(["unpack"])
    with pytest.raises(ValueError, match="--from=.* holds no <part>.tgz.NNN pieces"):
        carry_parts.main(["unpack", "--from", str(tmp_path)])
    with pytest.raises(ValueError, match="max_mb=0.0 is invalid"):
        carry_parts.pack(str(tmp_path), str(tmp_path / "out"), max_mb=0.0)
    with pytest.raises(ValueError, match="max_total_mb=-1.0 is invalid"):
        carry_parts.pack(str(tmp_path), str(tmp_path / "out"), max_total_mb=-1.0)
    assert carry_parts.pack(str(tmp_path), str(tmp_path / "out"), log=lambda s: None) == []
    with pytest.raises(ValueError, match=r"logdir=.*nothing' holds no checkpoints folder"):
        driver.learner_only_checkpoint(str(tmp_path / "nothing"), str(tmp_path / "dest"))
    assert not os.path.exists(tmp_path / "nothing")  # nothing created in the source
