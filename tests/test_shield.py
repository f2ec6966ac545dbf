"""The planner's shield over a trained policy (agents/shield.py) and eval.py --shield: a policy that sweeps the UR5e
into an obstacle is overruled exactly from the step its rollout reaches the collision, the collision is avoided, the
backup sequence is followed on; without collisions to foresee (the point mass) the shielded policy is the policy;
options refused."""

import json

import jax
import jax.numpy as jnp
import numpy as np
import pytest

import envs
import eval as eval_cli
from agents import driver, planner, presets, shield

SWEEP = dict(backend="mujoco", episode_length=12, substeps=10, obstacle_radius=0.02)
"""UR5e reach-avoid on the native backend, 12 steps of 10 substeps, an obstacle of radius 2 cm."""
AHEAD = 18
"""The obstacle sits AHEAD times the end effector's first-step displacement along its path: the sweeping policy
first collides on step 7 (measured on this config; `test_the_sweep_first_collides_on_step_7` holds it)."""
COLLIDES_AT = 7


def _sweep(obs):
    """A stand-in for a trained policy: the shoulder pan joint turned at full action, whatever it observes."""
    return jnp.zeros((6,)).at[0].set(1.0)


@pytest.fixture(scope="module")
def sweep_env():
    """(batched env, jitted step, start with the obstacle placed on the end effector's path), one env."""
    env = envs.wrap(envs.make("ur5e-reach-avoid", **SWEEP), autoreset=False)
    start, step = env.reset(jax.random.split(jax.random.PRNGKey(3), 1)), jax.jit(env.step)
    ee = lambda s: s.pipeline_state.site_xpos[:, env.unwrapped.robot.ee_site]
    moved = ee(step(start, jax.vmap(_sweep)(start.obs))) - ee(start)
    start = start.replace(info={**start.info, "obstacle_pos": ee(start) + AHEAD * moved})
    return env, step, start


def _run(step, start, act, memory, steps: int = SWEEP["episode_length"]):
    """Executes `act(state, key, memory) -> (actions, overruled, memory)`: (states after each step, actions,
    overruled flags, the memory after each step)."""
    state, states, actions, flags, memories = start, [], [], [], []
    for key in jax.random.split(jax.random.PRNGKey(0), steps):
        action, overruled, memory = act(state, key, memory)
        state = step(state, action)
        states.append(state)
        actions.append(action)
        flags.append(np.asarray(overruled))
        memories.append(memory)
    return states, actions, np.stack(flags), memories


@pytest.fixture(scope="module")
def swept(sweep_env):
    """The unshielded sweep's and the shielded sweep's (16 samples x 4 steps) executed steps."""
    env, step, start = sweep_env
    config = planner.PlannerConfig(samples=16, horizon=4)
    one = lambda s, k, b: shield.shield_one(env.env.step, _sweep, s, k, b, config)
    shielded = jax.jit(lambda s, k, b: jax.vmap(one)(s, jax.random.split(k, 1), b))
    plain = _run(step, start, lambda s, k, b: (jax.vmap(_sweep)(s.obs), np.zeros(1, bool), b), ())
    backups = jax.vmap(lambda s: shield.no_backup(s, config, env.action_size))(start)
    return plain, _run(step, start, shielded, backups)


def _collision_step(states):
    """The first step (1-based) whose obstacle_collision is set, or None."""
    hits = np.array([float(s.metrics["obstacle_collision"][0]) for s in states])
    return int(hits.argmax()) + 1 if hits.any() else None


def test_the_sweep_first_collides_on_step_7(swept):
    (plain_states, _, _, _), _ = swept
    assert _collision_step(plain_states) == COLLIDES_AT


def test_the_shielded_sweep_does_not_collide(swept):
    _, (states, _, _, _) = swept
    assert _collision_step(states) is None


OVERRULED_FROM = COLLIDES_AT - 4
"""The first step (0-based) whose 4-step rollout reaches the collision on step 7: the policy's rollout from the state
after 3 steps covers steps 4-7."""


def test_the_shield_leaves_the_policy_alone_while_its_rollout_is_clear(swept):
    _, (_, _, flags, _) = swept
    assert not flags[:OVERRULED_FROM].any()


def test_the_shield_overrules_the_policy_from_the_step_its_rollout_collides(swept):
    _, (_, _, flags, _) = swept
    assert flags[OVERRULED_FROM]


def test_an_action_left_alone_is_the_policys_bit_for_bit(swept):
    _, (_, actions, _, _) = swept
    np.testing.assert_array_equal(np.asarray(actions[0][0]), np.asarray(_sweep(None)))


def test_an_overruled_steps_backup_is_its_sequence_moved_on_with_the_last_action_repeated(swept):
    _, (_, _, _, memories) = swept
    plan = memories[OVERRULED_FROM].plan
    np.testing.assert_array_equal(np.asarray(plan[0, -1]), np.asarray(plan[0, -2]))


def test_an_overruled_step_marks_its_backup_active(swept):
    _, (_, _, _, memories) = swept
    assert bool(memories[OVERRULED_FROM].active[0])


def test_a_clear_step_leaves_no_backup_active(swept):
    _, (_, _, _, memories) = swept
    assert not bool(memories[0].active[0])


def test_the_backup_counts_the_steps_overruled(swept):
    _, (_, _, flags, memories) = swept
    assert float(memories[-1].overruled[0]) == flags[:, 0].sum()


def test_the_next_step_searches_around_the_backup(sweep_env, swept):
    """With the backup active and next to no noise every sample is the backup itself: its first action acts."""
    env, _, _ = sweep_env
    _, (states, _, _, memories) = swept
    config = planner.PlannerConfig(samples=2, horizon=4, noise=1e-9)
    one = lambda s, b: shield.shield_one(env.env.step, _sweep, s, jax.random.PRNGKey(1), b, config)
    state, backup = jax.tree.map(lambda x: x[0], (states[OVERRULED_FROM], memories[OVERRULED_FROM]))
    action, _, _ = jax.jit(one)(state, backup)
    np.testing.assert_allclose(np.asarray(action), np.asarray(backup.plan[0]), atol=1e-6)


@pytest.mark.parametrize("horizon, fails", [(COLLIDES_AT - 1, False), (COLLIDES_AT, True)])
def test_a_rollout_fails_exactly_when_its_horizon_reaches_the_collision(sweep_env, horizon, fails):
    env, _, start = sweep_env
    one = jax.tree.map(lambda x: x[0], start)
    _, failed = jax.jit(lambda s: shield.policy_rollout(env.env.step, _sweep, s, horizon))(one)
    assert bool(failed) is fails


def test_the_cost_is_the_rollout_plus_the_planners_samples():
    assert shield.model_steps_per_step(planner.PlannerConfig(samples=8, horizon=5, iterations=2)) == 85


def test_an_unbatched_env_is_refused():
    with pytest.raises(ValueError, match="allowed is a batched env"):
        shield.make_unit_act(envs.make("point-mass"), None, planner.PlannerConfig())


# ------------------------------------------------------------------------------------------------
# eval.py --shield


@pytest.fixture(scope="module")
def point_export(tmp_path_factory):
    """A 1-seed point-mass PPO run (a few seconds)."""
    logdir = tmp_path_factory.mktemp("shield_point") / "run"
    driver.train(presets.make_config("point-mass-ppo", num_timesteps=5120, seeds=1, eval_envs=16, logdir=str(logdir),
                                     tensorboard=False, progress=False))
    return str(logdir)


@pytest.fixture(scope="module")
def point_reports(point_export, tmp_path_factory):
    """eval.py's JSON reports of the export, unshielded and shielded (8 samples x 4 steps), on the same episodes."""
    out = tmp_path_factory.mktemp("shield_eval")
    common = ["--checkpoint", point_export, "--num-envs", "8"]
    eval_cli.main(common + ["--json", str(out / "plain.json")])
    eval_cli.main(common + ["--shield", "--planner.samples", "8", "--planner.horizon", "4",
                            "--json", str(out / "shielded.json")])
    return [json.loads((out / f"{name}.json").read_text())["evaluations"][0] for name in ("plain", "shielded")]


def test_without_collisions_to_foresee_the_shielded_policy_is_the_policy(point_reports):
    """The point mass reports no collisions, so no rollout fails and every action is the policy's."""
    plain, shielded = point_reports
    own = {name: value for name, value in shielded["units"][0]["metrics"].items() if name != "overruled_steps"}
    assert own == plain["units"][0]["metrics"]


def test_without_collisions_to_foresee_no_step_is_overruled(point_reports):
    _, shielded = point_reports
    assert shielded["units"][0]["metrics"]["overruled_steps"] == 0.0


def test_an_unshielded_report_counts_no_overruled_steps(point_reports):
    plain, _ = point_reports
    assert "overruled_steps" not in plain["units"][0]["metrics"]


def test_the_report_names_the_shield(point_reports):
    _, shielded = point_reports
    assert shielded["policy"]["kind"] == "shielded"


def test_the_report_gives_the_rollout_plus_the_samples_as_the_cost(point_reports):
    _, shielded = point_reports
    assert shielded["policy"]["model_steps_per_step"] == 36


def test_shield_with_a_baseline_is_refused():
    with pytest.raises(ValueError, match="--shield is invalid with --policy standstill"):
        eval_cli.main(["--env", "point-mass", "--policy", "standstill", "--shield", "--num-envs", "4"])


def test_shield_with_stochastic_actions_is_refused(point_export):
    with pytest.raises(ValueError, match="--stochastic is invalid with --shield"):
        eval_cli.main(["--checkpoint", point_export, "--shield", "--stochastic", "--num-envs", "4"])


def test_planner_options_without_the_shield_are_refused_for_a_checkpoint(point_export):
    with pytest.raises(ValueError, match=r"allowed only with --policy mppi or --checkpoint PATH --shield"):
        eval_cli.main(["--checkpoint", point_export, "--planner.samples", "8", "--num-envs", "4"])
