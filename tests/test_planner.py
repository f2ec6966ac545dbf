"""The MPPI planner (agents/planner.py), its eval.py policy and tools/planner_table.py: a known optimum on the point
mass, better than standing still on a small arm config, no effect on the state it plans from, options refused by
name."""

import json

import jax
import jax.numpy as jnp
import numpy as np
import pytest

import envs
import eval as eval_cli
from agents import baselines, driver, evaluation, planner, presets
from tools import planner_table


# ------------------------------------------------------------------------------------------------
# Options


@pytest.mark.parametrize("field, value", [("samples", 1), ("horizon", 0), ("iterations", 0), ("temperature", 0.0),
                                          ("noise", -0.1), ("discount", 1.5), ("samples", 2.5)])
def test_an_impossible_option_is_refused_naming_its_field(field, value):
    with pytest.raises(ValueError, match=rf"^{field}={value!r} is invalid"):
        planner.PlannerConfig(**{field: value})


def test_the_cost_is_samples_times_horizon_times_iterations():
    assert planner.PlannerConfig(samples=8, horizon=5, iterations=3).model_steps_per_step == 120


def test_an_unbatched_env_is_refused():
    with pytest.raises(ValueError, match="allowed is a batched env"):
        planner.make_act(envs.make("point-mass"), planner.PlannerConfig())


def test_the_weights_follow_the_best_return_at_a_small_temperature():
    w = planner.mppi_weights(jnp.array([0.0, 1.0, 0.5]), 0.01)
    assert float(w[1]) == pytest.approx(1.0, abs=1e-6)


def test_equal_returns_weigh_equally():
    w = planner.mppi_weights(jnp.array([2.0, 2.0, 2.0, 2.0]), 0.05)
    np.testing.assert_allclose(np.asarray(w), 0.25, rtol=1e-6)


def test_a_return_stops_counting_after_the_simulated_episode_ends():
    """Point mass in 1-D from 1.45 m: a step of +1 leaves the arena (|x| > 1.5): termination, reward 0, and what
    follows is not counted; a step of -1 stays in and collects exp(-alpha * distance) every step."""
    env = envs.wrap(envs.make("point-mass", dim=1), autoreset=False)
    state = _placed(env, start=1.45, goal=1.0, n=1)
    one = jax.tree.map(lambda x: x[0], state)
    returns = planner.sequence_returns(env.env.step, one, jnp.array([[[1.0], [-1.0]], [[-1.0], [-1.0]]]), 1.0)
    assert float(returns[0]) == 0.0
    expected = np.exp(-5.0 * abs(1.35 - 1.0)) + np.exp(-5.0 * abs(1.25 - 1.0))
    assert float(returns[1]) == pytest.approx(expected, rel=1e-5)


# ------------------------------------------------------------------------------------------------
# The point mass: the fastest path is known


def _placed(env, start: float, goal: float, n: int):
    """`n` 1-D point-mass envs at `start` with the goal at `goal` (reset, then moved)."""
    state = env.reset(jax.random.split(jax.random.PRNGKey(0), n))
    pos = jnp.full((n, 1), start)
    goal_arr = jnp.full((n, 1), goal)
    return state.replace(pipeline_state={"pos": pos}, obs=jnp.concatenate([pos, goal_arr, goal_arr - pos], -1),
                         info={**state.info, "goal": goal_arr, "reached": jnp.zeros((n,))})


def _rollout(env, act, memory, start, steps: int, seed: int = 0, step=None):
    """Executes the planner `steps` steps (`step`: the jitted env step): (states after each step, the actions)."""
    state, plans, states, actions = start, memory(start), [], []
    step = step or jax.jit(env.step)
    for key in jax.random.split(jax.random.PRNGKey(seed), steps):
        action, plans = act(None, state, start, key, plans)
        state = step(state, action)
        states.append(state)
        actions.append(action)
    return states, actions


@pytest.fixture(scope="module")
def point_arrivals():
    """The step at which each of 8 1-D point-mass envs first reaches its goal: from 0 to a goal at 0.75 m with
    radius 0.1 m, at most 0.1 m per step (dt 0.1 s, 1 m/s): 7 steps at full speed (0.7 m, 0.05 m away) is the
    earliest arrival possible. The planner refines 3 times per step, as one iteration from a standstill plan
    accelerates late (its first action weighs noise over the whole horizon)."""
    env = envs.wrap(envs.make("point-mass", dim=1), autoreset=False)
    act, memory = planner.make_act(env, planner.PlannerConfig(samples=64, horizon=10, iterations=3, noise=0.5))
    states, _ = _rollout(env, jax.jit(act), memory, _placed(env, 0.0, 0.75, 8), 11)
    reached = np.stack([np.asarray(s.info["reached"]) for s in states])  # (steps, envs)
    assert reached[-1].all(), reached[-1]
    return reached.argmax(axis=0) + 1


def test_no_point_mass_arrives_before_the_physical_limit(point_arrivals):
    assert point_arrivals.min() >= 7


def test_the_planner_arrives_within_one_step_of_the_fastest_path(point_arrivals):
    assert point_arrivals.max() <= 8


# ------------------------------------------------------------------------------------------------
# A small arm config on the native backend


ARM = dict(backend="mujoco", episode_length=10, substeps=10)
"""UR5e reach, 10 steps of 10 substeps: seconds per rollout on a CPU."""


@pytest.fixture(scope="module")
def arm_rollout():
    """(jitted env step, start, states, actions) of the planner (16 samples x 4 steps) on 4 UR5e reach envs, and
    the states of the standstill baseline (`agents.baselines`) from the same starts."""
    env = envs.wrap(envs.make("ur5e-reach", **ARM), autoreset=False)
    act, memory = planner.make_act(env, planner.PlannerConfig(samples=16, horizon=4))
    start, step = env.reset(jax.random.split(jax.random.PRNGKey(3), 4)), jax.jit(env.step)
    states, actions = _rollout(env, jax.jit(act), memory, start, ARM["episode_length"], step=step)
    still = baselines.make_act(env)
    standing, _ = _rollout(env, jax.jit(lambda p, s, s0, k, m: (still(baselines.index("standstill"), s, s0, k), m)),
                           lambda s0: (), start, ARM["episode_length"], step=step)
    return step, start, states, actions, standing


def test_the_planner_ends_closer_to_the_target_than_standing_still(arm_rollout):
    _, _, states, _, standing = arm_rollout
    planned = np.asarray(states[-1].metrics["distance"])
    still = np.asarray(standing[-1].metrics["distance"])
    assert np.all(planned < still - 0.02), (planned, still)


def test_the_planner_collects_more_reward_than_standing_still(arm_rollout):
    _, _, states, _, standing = arm_rollout
    planned = sum(np.asarray(s.reward) for s in states)
    still = sum(np.asarray(s.reward) for s in standing)
    assert np.all(planned > still), (planned, still)


def test_the_executed_trajectory_is_a_replay_of_the_chosen_actions(arm_rollout):
    """Planning simulates copies of the state: stepping the env with the chosen actions alone gives the same poses."""
    step, start, states, actions, _ = arm_rollout
    state = start
    for action, executed in zip(actions, states):
        state = step(state, action)
        np.testing.assert_array_equal(np.asarray(state.pipeline_state.qpos), np.asarray(executed.pipeline_state.qpos))


# ------------------------------------------------------------------------------------------------
# eval.py --policy mppi and the table tool


def test_eval_cli_reports_the_planner_and_its_cost(tmp_path):
    out = tmp_path / "mppi.json"
    eval_cli.main(["--env", "point-mass", "--policy", "mppi", "--planner.samples", "8", "--planner.horizon", "4",
                   "--num-envs", "8", "--json", str(out)])
    report = json.loads(out.read_text())["evaluations"][0]
    assert report["policy"]["model_steps_per_step"] == 32


def test_eval_cli_refuses_planner_options_for_a_baseline():
    with pytest.raises(ValueError, match="--planner.* options are invalid with --policy random"):
        eval_cli.main(["--env", "point-mass", "--policy", "random", "--planner.samples", "8", "--num-envs", "4"])


def test_eval_cli_refuses_an_unknown_policy_naming_the_planner():
    with pytest.raises(ValueError, match="allowed are random, standstill, pseudo_ik, mppi"):
        eval_cli.main(["--env", "point-mass", "--policy", "planner", "--num-envs", "4"])


def test_a_budget_is_samples_x_horizon():
    assert planner_table.parse_budget("64x16") == (64, 16)


@pytest.mark.parametrize("text", ["64", "64x", "ax16", "1x16"])
def test_a_malformed_or_impossible_budget_is_refused(text):
    with pytest.raises(ValueError):
        planner_table.parse_budget(text)


@pytest.fixture(scope="module")
def point_export(tmp_path_factory):
    """A 2-seed point-mass PPO run (a few seconds): the export the table compares the planner with."""
    logdir = tmp_path_factory.mktemp("planner_point") / "run"
    driver.train(presets.make_config("point-mass-ppo", num_timesteps=5120, seeds=2, eval_envs=16, logdir=str(logdir),
                                     tensorboard=False, progress=False))
    return logdir


@pytest.fixture(scope="module")
def table_run(point_export, tmp_path_factory):
    out = tmp_path_factory.mktemp("planner_table")
    planner_table.main(["--checkpoint", str(point_export), "--out", str(out), "--episodes", "8", "--seeds", "2",
                        "--samples", "8", "--horizon", "4", "--budgets", "4x2", "8x4"])
    return out, json.loads((out / "planner.json").read_text())


def test_the_table_evaluates_the_export_on_the_planners_episodes(point_export, table_run):
    _, report = table_run
    [task] = report["tasks"]
    policy = evaluation.checkpoint_policy(str(point_export))
    direct = evaluation.run(policy, "point-mass", envs.make_config("point-mass", policy.train_env_config), 8,
                            report["eval_seeds"])
    assert task["rows"][1]["summary"]["distance"]["mean"] == pytest.approx(direct.summary()["distance"]["mean"],
                                                                           rel=1e-6)


def test_the_gap_is_the_planner_minus_the_best_export(table_run):
    _, report = table_run
    [task] = report["tasks"]
    reached = [r["summary"]["target_reached"]["mean"] for r in task["rows"]]
    assert planner_table.gap(task) == pytest.approx(100.0 * (reached[0] - max(reached[1:])))


def test_the_sweep_rows_carry_their_budgets(table_run):
    _, report = table_run
    assert [r["model_steps_per_step"] for r in report["budgets"]] == [8, 32]


def test_the_table_and_the_budget_plot_are_written(table_run):
    out, _ = table_run
    assert (out / "budget.png").stat().st_size > 5_000


def test_the_table_has_a_row_per_policy_and_the_gap(table_run):
    out, _ = table_run
    table = (out / "table.md").read_text()
    assert "| point-mass | mppi | 16 |" in table


def test_the_sweep_reuses_the_tables_planner_row_at_the_tables_budget(table_run):
    _, report = table_run
    assert report["budgets"][1]["summary"] == report["tasks"][0]["rows"][0]["summary"]


def test_runs_made_apart_merge_into_one_table(table_run, tmp_path):
    out, report = table_run
    other = dict(report, budgets=[], budget_task=None, tasks=[dict(report["tasks"][0], task="point-mass, again")])
    (tmp_path / "other.json").write_text(json.dumps(other))
    planner_table.main(["--from-json", str(out / "planner.json"), str(tmp_path / "other.json"), "--out",
                        str(tmp_path / "merged")])
    merged = json.loads((tmp_path / "merged" / "planner.json").read_text())
    assert [t["task"] for t in merged["tasks"]] == ["point-mass", "point-mass, again"]


def test_a_task_in_two_runs_keeps_the_first_runs_rows(table_run, tmp_path):
    out, report = table_run
    other = dict(report, budgets=[], budget_task=None, tasks=[dict(report["tasks"][0], rows=[])])
    (tmp_path / "other.json").write_text(json.dumps(other))
    planner_table.main(["--from-json", str(tmp_path / "other.json"), str(out / "planner.json"), "--out",
                        str(tmp_path / "merged")])
    merged = json.loads((tmp_path / "merged" / "planner.json").read_text())
    assert [len(t["rows"]) for t in merged["tasks"]] == [0]


@pytest.fixture
def superseded_sweep(table_run, tmp_path):
    """A merge whose first file re-ran the swept task with the planner row alone: the table takes that run's rows."""
    out, report = table_run
    rerun = dict(report, budgets=[], budget_task=None, code="rerun",
                 tasks=[dict(report["tasks"][0], rows=report["tasks"][0]["rows"][:1])])
    (tmp_path / "rerun.json").write_text(json.dumps(rerun))
    planner_table.main(["--from-json", str(tmp_path / "rerun.json"), str(out / "planner.json"), "--out",
                        str(tmp_path / "merged")])
    return report, json.loads((tmp_path / "merged" / "planner.json").read_text())


def test_a_sweep_whose_task_was_rerun_names_its_own_run(superseded_sweep):
    report, merged = superseded_sweep
    assert merged["budget_source"] == f"the sweep's own run (code {report['code']}, {report['date']})"


def test_a_sweep_whose_task_was_rerun_keeps_its_own_rows_as_the_plots_reference(superseded_sweep):
    report, merged = superseded_sweep
    assert merged["budget_reference"]["rows"] == report["tasks"][0]["rows"]


def test_a_sweep_of_the_tables_own_run_has_no_source_note(table_run, tmp_path):
    out, _ = table_run
    planner_table.main(["--from-json", str(out / "planner.json"), "--out", str(tmp_path / "merged")])
    assert "budget_source" not in json.loads((tmp_path / "merged" / "planner.json").read_text())


def test_merging_two_sweeps_is_refused(table_run, tmp_path):
    out, _ = table_run
    with pytest.raises(ValueError, match="2 budget sweeps"):
        planner_table.main(["--from-json", str(out / "planner.json"), str(out / "planner.json"), "--out", str(tmp_path)])


def test_a_merged_report_names_its_sources_code_device_and_date(table_run, tmp_path):
    out, report = table_run
    planner_table.main(["--from-json", str(out / "planner.json"), "--out", str(tmp_path / "merged")])
    merged = json.loads((tmp_path / "merged" / "planner.json").read_text())
    assert (merged["code"], merged["device"], merged["date"]) == (report["code"], report["device"], report["date"])
