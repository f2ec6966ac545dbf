"""The experiment registry (tools/registry_*.py, tools/experiment_spec.py): every registered run builds a valid
config and its train.py command parses back to it, the registry spells settings as the presets do, recorded parts
still read as their runs, bad overrides and names are refused, and docs/experiments.md's recipe registers."""

import dataclasses
import os

import pytest

import train
from agents import presets
from experiment_parts import TOY
from tools import experiment_spec as spec
from tools import experiment_state as state
from tools import experiment_tables as tables
from tools import experiments as ex

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))  # the checkout


@pytest.mark.parametrize("name", sorted(spec.EXPERIMENTS))
def test_registered_runs_are_valid_and_their_commands_parse_back(name):
    exp = spec.EXPERIMENTS[name]
    state.validate_experiment(exp)
    for run in exp.runs:
        logdir = os.path.join(state.RUNS_DIR, name, run.name)
        assert train.parse(run.train_args(logdir)) == run.config(logdir), run.name
        part = os.path.join(logdir, state.part_name(2, 1))
        assert train.parse(run.train_args(part, first_seed=2, seeds=1)) == run.config(part, first_seed=2, seeds=1)


def test_every_run_has_a_budget_and_a_seed_count_its_experiment_explains():
    """1 to 5 seeds a run (5 for the paper's stated numbers, 3 for curve comparisons); an experiment with rows of
    fewer than 3 says why in its note."""
    for name, exp in spec.EXPERIMENTS.items():
        for run in exp.runs:
            assert run.budget() > 0, (name, run.name)
            assert 1 <= run.seeds <= 5, (name, run.name, run.seeds)
        if any(run.seeds < 3 for run in exp.runs):
            assert "seed" in exp.note.lower(), name


def test_the_registry_spells_the_plus_observations_as_the_presets_do():
    from agents.presets import make_config
    from tools import registry_obstacles as obstacles
    from tools import registry_paper_tasks as paper_tasks

    assert make_config("ur5e-reach-ppo-plus").env.observation == paper_tasks.PLUS_OBS
    assert make_config("ur5e-reach-avoid-ppo-plus").env.observation == paper_tasks._PLUS_AVOID_OBS
    for env in ("ur5e-reach", "panda-reach"):
        assert make_config(f"{env}-sac-fast").env.observation == paper_tasks.PLUS_OBS
    for env in ("ur5e-reach-avoid", "panda-reach-avoid"):
        assert make_config(f"{env}-sac-fast").env.observation == paper_tasks._PLUS_AVOID_OBS
    assert make_config("panda-reach-avoid-ppo-moving3").env.observation == obstacles._MOVING3_OBS
    assert make_config("ur5e-reach-avoid-ppo-moving3").env.observation == obstacles._MOVING3_PLUS_OBS


@pytest.mark.parametrize("field", ["num_obstacles", "obstacle_motion", "obstacle_radius_range", "obstacle_speed_range"])
def test_the_registry_spells_the_moving_obstacles_as_the_presets_do(field):
    from agents.presets import make_config
    from tools import registry_obstacles as obstacles

    assert obstacles._MOVING3["env." + field] == getattr(make_config("ur5e-reach-avoid-ppo-moving3").env, field)


def test_every_recorded_part_still_reads_as_its_registry_run():
    """A preset edited after its runs trained must leave those rows overrides that keep their config: every part
    recorded under results/experiments (finished ones only) reads as its run's and done, not `changed` (a field a
    resume may not change) nor `partial` (a budget the override no longer pins)."""
    checked = 0
    for exp in spec.EXPERIMENTS.values():
        for run in exp.runs:
            folder = state.record_folder(os.path.join(ROOT, state.OUT_DIR), exp.name, run.name)
            for name in sorted(os.listdir(folder)) if os.path.isdir(folder) else ():
                span = state.parse_part(name)
                if span is not None:
                    part = state.part_state(run, os.path.join(folder, name), *span)
                    assert part.status == "done", (exp.name, run.name, name, part.status, part.reason)
                    checked += 1
    assert checked >= 50  # the parts recorded under results/experiments


def test_table_names_a_budget_other_than_the_presets():
    preset = presets.PRESETS["panda-reach-sac-fast"].run["num_timesteps"]
    run = spec.Run("x", "panda-reach-sac-fast", {"algo.compute_dtype": "float32", "env.observation": ("joint_pos", "ee_pos")},
                 num_timesteps=100_000_000)
    assert preset == 200_000_000
    assert tables.describe_overrides(run) == "algo.compute_dtype=float32, env.observation=joint_pos+ee_pos, num_timesteps=100M"
    assert tables.describe_overrides(dataclasses.replace(run, num_timesteps=preset)) == (
        "algo.compute_dtype=float32, env.observation=joint_pos+ee_pos")  # the preset's own budget: not repeated
    assert tables.describe_overrides(spec.Run("y", "panda-reach-sac-fast")) == ""


def test_bad_overrides_and_names_raise():
    with pytest.raises(ValueError, match="env.no_such_field"):
        spec.Run("x", "point-mass-ppo", {"env.no_such_field": 1}).config()
    with pytest.raises(ValueError, match="seeds and budget are Run fields"):
        spec.Run("x", "point-mass-ppo", {"seeds": 3}).config()
    with pytest.raises(ValueError, match="goal_radius"):
        state.validate_experiment(spec.Experiment("bad", "", "", (spec.Run("x", "point-mass-ppo", {"env.goal_radius": -1.0}),)))
    with pytest.raises(ValueError, match="registered twice"):
        spec.register(TOY, {"toy": TOY})
    with pytest.raises(ValueError, match=r"curve_groups row 'r' names runs \['a', 'zzz'\]: allowed are one or more of a, b"):
        spec.register(dataclasses.replace(TOY, curve_groups=(("r", ("a", "zzz")),)), {})
    with pytest.raises(ValueError, match=r"curve_axes=\('minutes',\) holds 'minutes': allowed are one or more of env_steps, wall_clock"):
        spec.register(dataclasses.replace(TOY, curve_axes=("minutes",)), {})
    with pytest.raises(ValueError, match=r"curve_axes=\(\) holds '\(\)'"):
        spec.register(dataclasses.replace(TOY, curve_axes=()), {})
    with pytest.raises(ValueError, match="run 'zzz' is not in experiment 'toy'"):
        state.select(["toy/zzz"], {"toy": TOY})
    with pytest.raises(ValueError, match="experiment 'zzz' is unknown"):
        state.select(["zzz"], {"toy": TOY})
    # Options another action would take are refused before anything is read.
    for argv, message in ((["list", "--time", "60"], "--time with list is meaningless: allowed is `launch`"),
                          (["build", "--max-seeds", "2"], "--max-seeds with build is meaningless: allowed is `launch` or "
                                                          "`run` or `commands`"),
                          (["run", "--executor", "local"], "--executor with run is meaningless: allowed is `launch`"),
                          (["record", "--runs-dir", "/nonexistent"], "--runs-dir='/nonexistent' is not a folder"),
                          (["launch", "--time", "0"], r"time_min=0 is impossible: allowed is a whole number >= 1"),
                          (["launch", "--slurm-arg", "account"], r"--slurm-arg='account' is invalid: allowed is KEY=VALUE"),
                          (["launch", "--executor", "local", "--wait"], "--wait with --executor local is meaningless"),
                          (["launch", "--time", "1", "--signal-delay", "60"], r"signal_delay_s=60 is impossible with "
                                                                               r"time_min=1"),
                          (["record", "--all"], "--all with record is meaningless: allowed is `commands`"),
                          (["commands", "--no-build"], "--no-build with commands is meaningless")):
        with pytest.raises(ValueError, match=message):
            ex.main(argv)
    state.validate_experiment(TOY)
    for cross, message in ((spec.Cross("zzz", "x", {}), "run 'zzz' is not in experiment 'toy'"),
                           (spec.Cross("a", "x", {"no_field": 1}), "env field 'no_field' is unknown for point-mass"),
                           (spec.Cross("a", "x", {"goal_radius": -1.0}), "goal_radius"),
                           (spec.Cross("a", "x/y", {}), "name='x/y' is invalid"),
                           (spec.Cross("a", "x", {}), r"env=\{\} with stochastic=False evaluates the run as trained again")):
        with pytest.raises(ValueError, match=message):
            state.validate_experiment(dataclasses.replace(TOY, cross=(cross,)))
    # A cross that moves obstacles under a run that observed their velocity as 0 in every episode is refused at
    # registration (its policies would read the motion through a normaliser fit to one value), not after training.
    static = spec.Run("static", "panda-reach-avoid-ppo-moving3", {"env.obstacle_motion": "static"})
    blind = spec.Run("blind", "panda-reach-avoid-ppo-moving3", {
        "env.obstacle_motion": "static", "env.observation": ("joint_pos", "ee_pos", "target_pos", "obstacle_pos")})
    avoid = spec.Experiment("avoid", "static and moving", "not in the paper", (static, blind))
    with pytest.raises(ValueError, match=r"cross 'static-on-moving': env=\{'obstacle_motion': 'linear'\} changes what "
                                         r"run 'static' observed as one value in training: obstacle_vel \(trained with "
                                         r"obstacle_motion='static', here varying\)"):
        state.validate_experiment(dataclasses.replace(avoid, cross=(spec.Cross("static", "static-on-moving",
                                                                          {"obstacle_motion": "linear"}),)))
    state.validate_experiment(dataclasses.replace(avoid, cross=(spec.Cross("blind", "blind-on-moving",
                                                                      {"obstacle_motion": "linear"}),)))
    assert spec.cli_option("algo.policy_hidden_sizes", (64, 64)) == ["--algo.policy-hidden-sizes", "64", "64"]
    assert spec.cli_option("tensorboard", False) == ["--no-tensorboard"]


def test_the_docs_recipe_for_an_experiment_registers_and_validates():
    """docs/experiments.md's "Add an experiment" block, run as written against a fresh registry."""
    with open(os.path.join(ROOT, "docs", "experiments.md")) as f:
        text = f.read()
    block = text.split("## Add an experiment", 1)[1].split("```python\n", 1)[1].split("```", 1)[0]
    registry = {}
    names = {"register": lambda exp: spec.register(exp, registry), "Experiment": spec.Experiment, "Run": spec.Run,
             "Cross": spec.Cross, "paper_row": spec.paper_row}
    exec(block, names)
    (exp,) = registry.values()
    state.validate_experiment(exp)
    assert exp.runs[0].paper == {"target_reached": 0.961, "self_collision": 0.022}  # the paper's UR5e reach PPO row
    assert exp.runs[1].budget() == 100_000_000
