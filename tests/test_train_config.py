"""The training config as a user makes it: presets and their command-line overrides, bad input refused before
anything compiles, the learner class in the program cache's key, and the next steps train.py suggests."""

import pytest

import envs
import train as train_cli
from agents import driver, presets
from agents.config import total_updates, validate
from agents.ppo import PPO, PPOConfig
from agents.sac import SACConfig
from eval_runs import QUIET

SHORT = 30_720  # 6 updates of the PPO probe preset


def _ppo_subclass():
    """A PPO subclass, a new class object on every call (as a notebook cell that is run again)."""

    class MyPPO(PPO):
        pass

    return MyPPO


def test_presets_set_their_env_options_and_the_command_line_overrides_them():
    """A preset's env options replace the env's defaults (the UR5e PPO presets' action scale 0.3, the
    absolute preset's action mode and observation); an option on the command line replaces the preset's."""
    assert envs.default_config("ur5e-reach").action_scale == 0.2
    for name in ("ur5e-reach-ppo", "ur5e-reach-avoid-ppo"):
        assert train_cli.parse([name]).env.action_scale == 0.3, name
    for name in ("panda-reach-ppo", "panda-reach-avoid-ppo", "ur5e-reach-sac", "ur5e-reach-ppo-cpu"):
        assert train_cli.parse([name]).env.action_scale == 0.2, name
    assert train_cli.parse(["ur5e-reach-ppo", "--env.action-scale", "0.25"]).env.action_scale == 0.25
    # the joint-limit penalty (not in the paper): the two UR5e PPO presets with the paper's observations only
    limits = {name: (env.w_joint_limit, env.joint_limit_margin) for name in
              ("ur5e-reach-ppo", "ur5e-reach-avoid-ppo", "ur5e-reach-ppo-plus", "panda-reach-ppo")
              for env in [train_cli.parse([name]).env]}
    assert limits == {"ur5e-reach-ppo": (0.05, 0.5), "ur5e-reach-avoid-ppo": (1.0, 0.5),
                      "ur5e-reach-ppo-plus": (0.0, 0.5), "panda-reach-ppo": (0.0, 0.5)}
    assert train_cli.parse(["ur5e-reach-ppo", "--env.w-joint-limit", "0"]).env.w_joint_limit == 0.0
    absolute = train_cli.parse(["ur5e-reach-absolute-ppo"])
    assert absolute.env.action == "absolute"
    assert absolute.env.observation[-1] == "prev_action"
    assert absolute.algo.updates_per_batch == 7
    assert absolute.algo.policy_hidden_sizes == (256,) * 4
    for name in ("ur5e-reach-sac", "ur5e-reach-sac-plus", "panda-reach-sac"):  # not stated in the paper; Brax's is 1
        assert train_cli.parse([name]).algo.grad_updates_per_step == 8, name
    plus = train_cli.parse(["panda-reach-ppo-plus"]).env.observation
    assert plus == train_cli.parse(["ur5e-reach-ppo-plus"]).env.observation
    assert plus[1] == "joint_sin_cos"
    assert plus[-1] == "self_dist"


def test_learner_cls_is_part_of_the_program_cache_key():
    """`driver.train(config, learner_cls=...)` builds its programs around that class; a redefined
    class compiles anew, the default class (given or not) reuses the default programs. Builds the
    programs only (nothing is compiled); tests/test_loop_train.py's NaN test trains with a replaced class."""
    config = presets.make_config("point-mass-ppo", num_timesteps=SHORT, eval_envs=0, **QUIET)
    default = driver.programs_for(config)
    assert type(default.learner) is PPO
    assert driver.programs_for(config, PPO) is default
    first, second = _ppo_subclass(), _ppo_subclass()
    programs = driver.programs_for(config, first)
    assert type(programs.learner) is first
    assert programs is not default
    assert driver.programs_for(config, first) is programs
    assert type(driver.programs_for(config, second).learner) is second
    assert programs.learner.total_updates == total_updates(config)  # PPO's constructor arguments
    sac = presets.make_config("point-mass-sac")
    assert type(driver.programs_for(sac).learner).__name__ == "SAC"


BAD_INPUTS = [
    (lambda: presets.make_config("ur5-reach-ppo"), r"preset='ur5-reach-ppo' is unknown: allowed are .*ur5e-reach-ppo"),
    (lambda: train_cli.parse(["no-such-preset"]), r"preset='no-such-preset' is unknown"),
    (lambda: train_cli.parse(["point-mass-ppo", "--algo.num-envs", "48"]),
     r"algo.num_envs=48 is invalid: it must divide algo.batch_size \* algo.num_minibatches = 512"),
    (lambda: train_cli.parse(["point-mass-ppo", "--algo.batch-size", "10", "--algo.num-minibatches", "3", "--algo.num-envs", "7"]),
     r"algo.num_envs=7 is invalid: it must divide .* = 30"),
    (lambda: PPOConfig(num_envs=6, batch_size=6, num_minibatches=2).validate(num_devices=4),
     r"algo.num_envs=6 is invalid: it must be divisible by the 4 devices"),
    (lambda: SACConfig(num_envs=12, batch_size=24, max_replay_size=1200).validate(num_devices=8), r"algo.num_envs=12 is invalid: .* 8 devices"),
    (lambda: train_cli.parse(["point-mass-ppo", "--devices", "64"]), r"devices=64 is invalid: allowed are 0 \(all\) to"),
    (lambda: train_cli.parse(["point-mass-ppo", "--algo.activation", "sigmoid"]), r"algo.activation='sigmoid' is invalid: allowed are 'swish'"),
    (lambda: train_cli.parse(["point-mass-ppo", "--algo.lr-schedule", "step"]), None),  # tyro: not a Literal choice
    (lambda: train_cli.parse(["point-mass-ppo", "--algo.discount", "1.5"]), r"algo.discount=1.5 is invalid: allowed is a number in \[0.0, 1.0\]"),
    (lambda: train_cli.parse(["point-mass-ppo", "--algo.value-hidden-sizes"]),
     r"algo.value_hidden_sizes=\(\) is invalid: allowed is a non-empty tuple"),
    (lambda: train_cli.parse(["point-mass-ppo", "--algo.kernel-init", "zeros"]), r"algo.kernel_init='zeros' is invalid: allowed are 'lecun_uniform'"),
    (lambda: train_cli.parse(["point-mass-ppo", "--algo.unroll-length", "0"]), r"algo.unroll_length=0 is invalid: allowed is an integer >= 1"),
    (lambda: train_cli.parse(["point-mass-ppo", "--num-timesteps", "ten"]), None),  # tyro: not an integer
    (lambda: train_cli.parse(["point-mass-ppo", "--seeds", "0"]), r"seeds=0 is invalid: allowed is an integer >= 1"),
    (lambda: train_cli.parse(["point-mass-ppo", "--env.goal-radius", "-1"]), r"goal_radius=-1.0 is invalid"),
    (lambda: presets.make_config("point-mass-ppo", env=None), r"env=NoneType does not fit env_name='point-mass'"),
    (lambda: train_cli.parse(["point-mass-sac", "--algo.batch-size", "24"]),
     r"algo.batch_size=24 is invalid with algo.num_envs=16: allowed are multiples or divisors"),
    (lambda: train_cli.parse(["point-mass-sac", "--algo.max-replay-size", "1000"]),
     r"algo.max_replay_size=1000 is invalid: allowed are multiples of algo.num_envs=16"),
    (lambda: train_cli.parse(["point-mass-sac", "--algo.min-replay-size", "64000"]), r"algo.min_replay_size=64000 is invalid"),
    (lambda: train_cli.parse(["point-mass-ppo", "--resume"]), r"logdir='' is invalid with resume=True"),
    (lambda: train_cli.parse(["point-mass-ppo", "--multi-device", "pmap"]), None),  # tyro: not a Literal choice
    (lambda: validate(presets.make_config("point-mass-ppo", multi_device="pmap")),
     r"multi_device='pmap' is unknown: allowed are shard_map, gspmd"),
    (lambda: train_cli.parse(["point-mass-ppo", "--episode-restarts", "brax"]), None),  # tyro: not a Literal choice
    (lambda: validate(presets.make_config("point-mass-ppo", episode_restarts="brax")),
     r"episode_restarts='brax' is unknown: allowed are fresh, first"),
]


@pytest.mark.parametrize("make, message", BAD_INPUTS)
def test_bad_input_fails_before_compiling(make, message, monkeypatch, tmp_path):
    monkeypatch.chdir(tmp_path)
    monkeypatch.setattr(driver, "build_programs", lambda *a, **k: pytest.fail("compiled despite bad input"))
    if message is None:
        with pytest.raises(SystemExit) as info:
            make()
        assert info.value.code == 2
        return
    with pytest.raises(ValueError, match=message):
        config = make()
        if config is not None:
            driver.train(config)


def test_resume_without_checkpoint_is_refused(tmp_path):
    config = presets.make_config("point-mass-ppo", logdir=str(tmp_path / "empty"), resume=True, **QUIET)
    with pytest.raises(ValueError, match="holds no checkpoint"):
        driver.train(config)


def test_next_steps_suggest_an_evaluation_sized_for_the_machine():
    cpu = train_cli.next_steps("runs/x", "cpu")
    assert "python eval.py --checkpoint runs/x --num-envs 64 " in cpu


def test_next_steps_keep_the_default_evaluation_on_a_gpu():
    assert "--num-envs" not in train_cli.next_steps("runs/x", "gpu")


def test_next_steps_name_the_extra_that_installs_tensorboard():
    assert 'tensorboard --logdir runs/x (pip install -e ".[tensorboard]")' in train_cli.next_steps("runs/x", "cpu")
