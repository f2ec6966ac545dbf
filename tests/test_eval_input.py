"""Bad input to eval.py: a ValueError with a one-line message (exit code 2 from the command line), before anything
compiles; a damaged export rebuilt from its full checkpoint.
"""

import dataclasses
import shutil

import jax
import numpy as np
import pytest

import eval as eval_cli
from agents import evaluation, export
from eval_runs import eval_process


@pytest.fixture
def no_compile(monkeypatch):
    """Evaluations are built (env, jitted function) but never run."""
    original = evaluation._evaluator.__wrapped__

    def building_only(*args):
        program = original(*args)
        return dataclasses.replace(program, evaluate=lambda *a, **k: pytest.fail("evaluated despite bad input"))

    monkeypatch.setattr(evaluation, "_evaluator", building_only)


def _corrupt(src, tmp_path, how):
    run = tmp_path / "corrupt"
    shutil.copytree(src, run)
    policy = max(run.glob("checkpoints/*/policy"), key=lambda p: int(p.parent.name))  # the newest: eval.py's pick
    if how == "npz":
        data = (policy / "policy.npz").read_bytes()
        (policy / "policy.npz").write_bytes(data[: len(data) // 2])
    elif how == "json":
        (policy / "policy.json").write_text("{not json")
    elif how == "shapes":
        with np.load(policy / "policy.npz") as f:
            arrays = {k: f[k] for k in f.files}
        arrays["policy/params/hidden_0/kernel"] = arrays["policy/params/hidden_0/kernel"][:, :, :7]
        np.savez(policy / "policy.npz", **arrays)
    elif how == "orbax":  # no export and a broken full checkpoint
        step = policy.parent
        shutil.rmtree(policy)
        (step / "state").mkdir(exist_ok=True)
        for f in (step / "state").rglob("*"):
            if f.is_file():
                f.write_bytes(b"garbage")
    return run


BAD = [
    (lambda d, t: ["--checkpoint", str(t / "nowhere")], r"does not exist"),
    (lambda d, t: ["--checkpoint", str(t)], r"holds no checkpoint and no policy export"),
    (lambda d, t: ["--checkpoint", str(_corrupt(d["arm"], t, "npz"))], r"corrupt or unreadable"),
    (lambda d, t: ["--checkpoint", str(_corrupt(d["arm"], t, "json"))], r"corrupt or unreadable: policy.json: JSONDecodeError"),
    (lambda d, t: ["--checkpoint", str(_corrupt(d["arm"], t, "shapes"))], r"do not match the network of its config"),
    (lambda d, t: ["--checkpoint", str(_corrupt(d["point"], t, "orbax"))], r"corrupt or unreadable"),
    (lambda d, t: ["--checkpoint", str(d["arm"]), "--env", "panda-reach"],
     r"trained on 'ur5e-reach' \(robot ur5e\): env='panda-reach' is another robot"),
    (lambda d, t: ["--checkpoint", str(d["point"]), "--env", "ur5e-reach"], r"is another robot"),
    (lambda d, t: ["--checkpoint", str(d["arm"]), "--env.observation", "joint_pos", "ee_pos"],
     r"takes observations of shape \(15,\) but env 'ur5e-reach' with observation=\('joint_pos', 'ee_pos'\) gives shape \(9,\)"),
    (lambda d, t: ["--checkpoint", str(d["arm"]), "--env", "ur5e-reach-avoid"],  # reach agent: own observation kept
     None),
    (lambda d, t: ["--checkpoint", str(d["arm"]), "--env", "ur5e-reach-avoid", "--env.observation", "joint_pos",
                   "ee_pos", "target_pos", "ee_to_target", "obstacle_pos"], r"shape \(15,\) .* gives shape \(18,\)"),
    # formerly the trained parts reordered, or another action mode, ran without a word
    (lambda d, t: ["--checkpoint", str(d["arm"]), "--env.observation", "ee_pos", "joint_pos", "target_pos", "ee_to_target"],
     r"cannot run with observation=\('ee_pos', 'joint_pos', 'target_pos', 'ee_to_target'\) \(trained: \('joint_pos', "
     r"'ee_pos', 'target_pos', 'ee_to_target'\)\): .*\(or --allow-env-mismatch"),
    (lambda d, t: ["--checkpoint", str(d["arm"]), "--env.action", "absolute"],
     r"cannot run with action='absolute' \(trained: 'relative'\)"),
    (lambda d, t: ["--checkpoint", str(d["arm"]), "--env.action", "absolute", "--allow-env-mismatch"], None),
    (lambda d, t: ["--checkpoint", str(d["point"] / "metrics.csv")], r"checkpoint '.*metrics.csv' is a file: allowed is"),
    (lambda d, t: ["--checkpoint", str(d["point"]), "--env.dim", "3"],
     r"takes observations of shape \(6,\) but env 'point-mass' gives shape \(9,\): allowed are env options giving "
     r"observations of shape \(6,\)"),
    (lambda d, t: ["--env", "ur5e-reach", "--policy", "ik"], r"policy='ik' is unknown: allowed are random, standstill, pseudo_ik"),
    (lambda d, t: ["--env", "ur5e-reach", "--policy", "pseudo_ik", "--env.target-sampling", "uniform"],
     r"pseudo_ik' is undefined with target_sampling='uniform'"),
    (lambda d, t: ["--env", "point-mass", "--policy", "pseudo_ik"], r"needs an arm environment"),
    (lambda d, t: ["--env", "ur5-reach", "--policy", "random"], r"env='ur5-reach' is unknown: allowed are"),
    (lambda d, t: ["--policy", "random"], r"--policy needs --env NAME"),
    (lambda d, t: ["--env", "point-mass", "--policy", "random", "--stochastic"], r"--stochastic is invalid with --policy random"),
    (lambda d, t: ["--env", "point-mass", "--policy", "random", "--compute-dtype", "float32"],
     r"--compute-dtype is invalid with --policy random"),
    (lambda d, t: ["--checkpoint", str(t / "nowhere"), "--compute-dtype", "float16"],  # refused before loading
     r"--compute-dtype='float16' is invalid: allowed are float32, bfloat16"),
    (lambda d, t: ["--checkpoint", str(d["point"]), "--compute-dtype", "bfloat16"],
     r"compute_dtype='bfloat16' is invalid for '.*' \(ppo, which has no compute_dtype setting\)"),
    (lambda d, t: ["--env", "ur5e-reach"], r"give exactly one of --checkpoint"),
    (lambda d, t: ["--env", "ur5e-reach", "--policy", "random", "--checkpoint", str(d["arm"])], r"give exactly one of"),
    (lambda d, t: ["--env", "ur5e-reach", "--policy", "random", "--num-envs", "0"], r"--num-envs=0 is invalid"),
    (lambda d, t: ["--env", "ur5e-reach", "--policy", "random", "--env.target-radius", "-1"], r"target_radius=-1.0 is invalid"),
    (lambda d, t: ["--env", "ur5e-reach", "--policy", "random", "--num-env", "4"], r"option '--num-env' is unknown"),
    (lambda d, t: ["--env", "point-mass", "--policy", "random", "--video", str(t / "v.gif")], r"--video needs an arm env"),
    (lambda d, t: ["--env", "ur5e-reach", "--policy", "random", "--video", str(t / "v.avi")], r"allowed are .mp4 and .gif"),
    (lambda d, t: ["--env", "ur5e-reach", "--policy", "random", "--video", str(t / "v.gif"), "--video-size", "big"],
     r"--video-size='big' is invalid"),
]


@pytest.mark.parametrize("make, message", BAD, ids=[f"bad{i}" for i in range(len(BAD))])
def test_bad_input_is_refused_with_a_clear_message(make, message, arm_export, point_run, tmp_path, no_compile):
    args = make({"arm": arm_export, "point": point_run}, tmp_path)
    if message is None:  # accepted: evaluation would start (and is stopped by the fixture)
        with pytest.raises(pytest.fail.Exception, match="evaluated despite bad input"):
            eval_cli.main(args + ["--num-envs", "2"])
        return
    with pytest.raises(ValueError, match=message) as info:
        eval_cli.main(args)
    assert "\n" not in str(info.value)


def test_mismatch_allowed_with_a_warning_naming_both(arm_export, no_compile):
    with pytest.warns(UserWarning, match=r"evaluated with action='absolute' \(trained: 'relative'\)"):
        with pytest.raises(pytest.fail.Exception, match="evaluated despite bad input"):
            eval_cli.main(["--checkpoint", str(arm_export), "--env.action", "absolute", "--allow-env-mismatch",
                           "--num-envs", "2"])


def test_damaged_export_is_rebuilt_from_the_full_checkpoint(point_run, tmp_path, capsys):
    """A damaged policy export with its full checkpoint beside it is written anew."""
    run = _corrupt(point_run, tmp_path, "npz")
    policy = evaluation.checkpoint_policy(str(run))
    err = capsys.readouterr().err
    assert "policy.npz: " in err, err
    assert "rebuilding it from the full checkpoint" in err, err
    original = export.load(str(point_run))
    for a, b in zip(jax.tree.leaves(original.state), jax.tree.leaves(policy.export.state)):
        np.testing.assert_array_equal(np.asarray(a), np.asarray(b))
    export.load(str(run))  # readable again


def test_help_lists_the_env_options_once_the_env_is_known(arm_export, capsys):
    """`eval.py --help`: eval.py's options; with a checkpoint (or --env): also its env's --env.<field>."""
    for args, env_option in ((["--help"], None), (["--checkpoint", str(arm_export), "--help"], "--env.workspace"),
                             (["--env", "point-mass", "-h"], "--env.episode-length")):
        with pytest.raises(SystemExit) as info:
            eval_cli.main(args)
        out = capsys.readouterr().out
        assert info.value.code == 0
        assert "--num-envs" in out
        assert "--checkpoint" in out
        assert ("--env.episode-length" in out) == (env_option is not None)
        assert env_option is None or env_option in out


def test_bad_option_values_exit_2():
    with pytest.raises(SystemExit) as info:  # tyro: not a workspace
        eval_cli.main(["--env", "ur5e-reach", "--policy", "random", "--env.workspace", "everywhere"])
    assert info.value.code == 2


def test_cli_error_is_one_line_with_exit_code_2(tmp_path):
    proc = eval_process("--checkpoint", str(tmp_path / "missing"), "--json", str(tmp_path / "o.json"))
    assert proc.returncode == 2
    assert proc.stderr.strip().count("\n") == 0
    assert proc.stderr.startswith("error: checkpoint ")
    assert "Traceback" not in proc.stderr
    assert not (tmp_path / "o.json").exists()
