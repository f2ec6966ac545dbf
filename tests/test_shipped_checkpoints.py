"""The checkpoints shipped under results/checkpoints/ load on a CPU and do what results/README.md says;
the headline tables there and in README.md quote the eval.py JSON files, and the cross-evaluation
tables in results/README.md quote tools/paper_tables.py's JSON files.

Every shipped export loads, fits its env and is the checkpoint that its results/*_eval.json
evaluated (the best seed, for single-seed exports).

The UR5e reach PPO policy (5 seeds, 150M env steps on an H200, action scale 0.3, discount 0.99, joint-limit
penalty 0.05) reached the 1 cm target in 95.7 % of 4,096 episodes per seed there. Here its first seed runs
16 full-size episodes (20 substeps, 125 steps) on the CPU and is compared with the baselines' rates from
results/baselines.json (5 x 4,096 episodes on the GPU): random and standstill (almost) never reach, the
pseudo-IK reaches 41.5 %.
"""

import dataclasses
import json
import os

import jax
import pytest

import envs
from agents import evaluation, presets
from tools import paper_tables, ship_checkpoint

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
UR5E_REACH = os.path.join(ROOT, "results", "checkpoints", "ur5e-reach-ppo")


def _baseline_reached(robot: str, target_radius: float) -> dict:
    with open(os.path.join(ROOT, "results", "baselines.json")) as f:
        rows = json.load(f)["rows"]
    return {row["agent"]: row["summary"]["target_reached"]["mean"] for row in rows
            if row["robot"] == robot and row["target_radius"] == target_radius and row["action"] == "absolute"}


def _first_seed(policy: evaluation.Policy) -> evaluation.Policy:
    one = dataclasses.replace(policy.export, state=jax.tree.map(lambda x: x[:1], policy.export.state))
    return dataclasses.replace(policy, units=policy.units[:1], export=one)


def test_shipped_ur5e_reach_checkpoint_far_above_the_baselines():
    policy = evaluation.checkpoint_policy(UR5E_REACH)
    assert policy.export.env_name == "ur5e-reach" and policy.export.env_steps == 150_077_440
    assert policy.units == [0, 1, 2, 3, 4]
    config = policy.train_env_config
    assert (config.workspace, config.init_range, config.target_radius, config.substeps) == ("full", "full", 0.01, 20)
    assert (config.action, config.action_scale) == ("relative", 0.3) and policy.export.config.algo.discount == 0.99
    assert (config.w_joint_limit, config.joint_limit_margin) == (0.05, 0.5)

    result = evaluation.run(_first_seed(policy), "ur5e-reach", config, num_envs=16).summary()
    baselines = _baseline_reached("ur5e", 0.01)
    assert baselines["random"] < 0.001 and baselines["standstill"] == 0.0 and 0.3 < baselines["pseudo_ik"] < 0.5
    # GPU, this seed: 0.962 reached, 0.025 self collision, 0.018 m over 4,096 episodes.
    assert result["target_reached"]["mean"] >= 0.5 > baselines["pseudo_ik"] + 0.05
    assert result["distance"]["mean"] < 0.25
    assert result["steps_in_target"]["mean"] > 20


SHIPPED = sorted(os.listdir(os.path.join(ROOT, "results", "checkpoints")))


def test_every_row_of_the_results_table_ships():
    assert SHIPPED == ["panda-reach-avoid-ppo", "panda-reach-ppo", "panda-reach-ppo-plus", "ur5e-reach-avoid-ppo",
                       "ur5e-reach-avoid-ppo-plus", "ur5e-reach-ppo", "ur5e-reach-ppo-plus", "ur5e-reach-sac",
                       "ur5e-reach-sac-plus"]


# Exports trained before their preset existed, with the options that the preset now sets (the test below checks
# that the algorithm config and env options equal the preset's): export name -> the preset in its config.
TRAINED_AS = {"panda-reach-ppo-plus": "panda-reach-ppo"}  # + --env.observation ... joint_sin_cos ... self_dist


@pytest.mark.parametrize("name", SHIPPED)
def test_shipped_checkpoint_loads_and_is_the_evaluated_run(name):
    """Each export fits its env, and results/<name>_eval.json (eval.py on the GPU) evaluated that very
    checkpoint; a single-seed export holds the best seed there."""
    policy = evaluation.checkpoint_policy(os.path.join(ROOT, "results", "checkpoints", name))
    # each export is named after the preset it was trained with
    assert TRAINED_AS.get(name, name) == policy.export.config.preset
    preset = presets.PRESETS[name]
    assert policy.train_env_name == preset.env_name and policy.export.config.algo == preset.algo
    assert all(getattr(policy.train_env_config, k) == v for k, v in preset.env.items())
    env = envs.from_config(policy.train_env_name, policy.train_env_config)
    evaluation.check_compatible(policy, policy.train_env_name, env)
    eval_json = os.path.join(ROOT, "results", name.replace("-", "_") + "_eval.json")
    with open(eval_json) as f:
        evaluated = json.load(f)["evaluations"][0]
    assert evaluated["policy"]["env_steps"] == policy.export.env_steps
    assert evaluated["num_envs"] == 4096 and evaluated["env_config"]["substeps"] == 20
    if len(policy.units) == 1:
        assert policy.units == [ship_checkpoint.best_seed(eval_json, policy.export.env_steps)]


HEADLINE_ROWS = {  # results/README.md row label -> (eval.py JSON, collision kinds in the row)
    "UR5e reach, 1 cm target": ("ur5e_reach_ppo_eval.json", ("self",)),
    "Panda reach, 1 cm target": ("panda_reach_ppo_eval.json", ("self",)),
    "UR5e reach-avoid, 2 cm, 0.1 m obstacle": ("ur5e_reach_avoid_ppo_eval.json", ("self", "obstacle")),
    "Panda reach-avoid, 2 cm, 0.1 m obstacle": ("panda_reach_avoid_ppo_eval.json", ("self", "obstacle")),
    "UR5e reach, SAC": ("ur5e_reach_sac_eval.json", ("self",)),
    "UR5e reach, 1 cm target, plus observations": ("ur5e_reach_ppo_plus_eval.json", ("self",)),
    "UR5e reach-avoid, 2 cm, 0.1 m obstacle, plus observations": ("ur5e_reach_avoid_ppo_plus_eval.json", ("self", "obstacle")),
    "Panda reach, 1 cm target, plus observations, discount 0.97": ("panda_reach_ppo_plus_eval.json", ("self",)),
    "UR5e reach, SAC, plus observations": ("ur5e_reach_sac_plus_eval.json", ("self",)),
}


def _percent(stats: dict) -> str:
    return f"{100 * stats['mean']:.1f} ± {100 * stats['std_units']:.1f} %"


def _results_table_rows() -> list[list[str]]:
    """The cells of every markdown table row in results/README.md."""
    with open(os.path.join(ROOT, "results", "README.md"), encoding="utf-8") as f:
        return [[c.strip() for c in line.split("|")[1:-1]] for line in f if line.startswith("| ")]


@pytest.mark.parametrize("label", sorted(HEADLINE_ROWS))
def test_results_tables_quote_the_evaluation_files(label):
    """The headline numbers in results/README.md and README.md are the ones in the eval.py JSON files."""
    name, kinds = HEADLINE_ROWS[label]
    with open(os.path.join(ROOT, "results", name)) as f:
        evaluated = json.load(f)["evaluations"][0]
    summary = evaluated["summary"]
    assert evaluated["num_envs"] == 4096 and summary["target_reached"]["units"] == 5
    expected = [_percent(summary["target_reached"])] + [
        f"{_percent(summary[kind + '_collision'])[:-2]} % {kind}" for kind in kinds]
    rows = [cells for cells in _results_table_rows() if cells[0] == label]
    assert len(rows) == 1, label
    cells = rows[0]
    assert cells[3] == expected[0] and cells[4] == ", ".join(expected[1:]), (cells, expected)
    assert cells[5] == f"{evaluated['policy']['env_steps'] / 1e6:.{0 if evaluated['policy']['env_steps'] >= 1e7 else 1}f}M"
    with open(os.path.join(ROOT, "README.md"), encoding="utf-8") as f:
        readme = f.read()
    assert " / ".join(e.split(" %")[0] + " %" for e in expected) in readme, expected


CROSS_TABLES = {  # paper_tables.py JSON -> (its row's first two README cells, index of the first "ours" cell, metrics)
    "workspace_generalization.json": (lambda r: [paper_tables.WORKSPACE_NAMES[r["trained"]],
                                                 paper_tables.WORKSPACE_NAMES[r["evaluated"]]],
                                      4, ("target_reached", "self_collision")),
    "obstacle_size.json": (lambda r: [r["trained"], f"{r['evaluated']:g}"], 3,
                           ("target_reached", "self_collision", "obstacle_collision")),
}


@pytest.mark.parametrize("name", sorted(CROSS_TABLES))
def test_cross_evaluation_tables_in_readme_quote_their_json(name):
    """Every row of a cross-evaluation table (paper_tables.py's JSON: 5 trained seeds x 4,096 episodes) appears
    once in results/README.md with the same numbers in the "ours" columns."""
    label, first, metrics = CROSS_TABLES[name]
    with open(os.path.join(ROOT, "results", name)) as f:
        rows = json.load(f)["rows"]
    lines = _results_table_rows()
    assert len(rows) >= 13
    for row in rows:
        assert row["num_envs"] == 4096 and row["summary"]["target_reached"]["units"] == 5
        key = label(row)
        found = [cells for cells in lines if cells[:2] == key and len(cells) >= first + len(metrics)]
        assert len(found) == 1, (name, key)
        assert found[0][first:first + len(metrics)] == [_percent(row["summary"][m]) for m in metrics], (name, key, found[0])
