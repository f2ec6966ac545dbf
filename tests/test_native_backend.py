"""The `mujoco` (native C) physics backend against a plain MuJoCo loop and against MJX (`envs.physics`).

Two findings shape the tolerances:
- The native backend rounds the state to float32 between env steps (it lives in the env state) and
  warm-starts each env step's constraint solver from a forward pass (`NativePhysics._last_acceleration`):
  a float64 C loop stays within 1e-5 rad of it over a 125-step UR5e episode; Panda joints pushed into
  their limits by random actions end up to ~3e-3 rad apart (EPISODE_TOLERANCE).
- MJX and C MuJoCo differ on the UR5e when an actuator's force is clamped at its `forcerange`
  (implicitfast's velocity derivative): the same step from the same state can differ by ~1e-2 rad
  under full relative actions. Without the clamp they agree to 1e-6 (`test_ur5e_difference_is_the_force_clamp`),
  so the UR5e comparisons use actions that stay inside the force range; the Panda (Euler) agrees under any action.

MJX compiles for tens of seconds per env on a CPU (and steps the Panda at about one env step per second),
so the MJX comparisons run on one env per robot, one of each task (`MJX_ENVS`): the backends differ only in
the physics, which is the same model for both tasks of a robot; the native backend runs every env.
"""

import jax
import jax.numpy as jnp
import mujoco
import numpy as np
import pytest
from mujoco import mjx

import envs
from mujoco_reference import colliding_configuration

ARM_ENVS = ["ur5e-reach", "panda-reach", "ur5e-reach-avoid", "panda-reach-avoid"]
MJX_ENVS = ["ur5e-reach", "panda-reach-avoid"]
N = 2
EPISODE_TOLERANCE = {"ur5e": 1e-4, "panda": 1e-2}
"""Joint position tolerance (rad) of the native backend against a plain mj_step loop over 125 steps."""
ACTION_BOUND = {"ur5e": 0.1, "panda": 1.0}
"""Largest |relative action| of the MJX comparisons (UR5e: inside the actuators' force range)."""


def _key(i):
    return jax.random.PRNGKey(i)


@pytest.fixture(scope="module")
def pair():
    """`get(name)` -> (native env wrapped without auto-reset, its jitted reset, native step, MJX step), for
    batches of N envs (the reset is the same JAX code on both backends: it steps no physics). Nothing compiles
    before a function is called."""
    cache = {}

    def get(name):
        if name not in cache:
            native, mjx_env = (envs.wrap(envs.make(name, backend=b), autoreset=False) for b in ("mujoco", "mjx"))
            cache[name] = (native, jax.jit(native.reset), jax.jit(native.step), jax.jit(mjx_env.step))
        return cache[name]

    return get


def test_backend_is_validated_and_auto_resolves_by_device():
    with pytest.raises(ValueError, match=r"backend='bullet' is invalid: allowed are 'auto', 'mjx', 'mujoco'"):
        envs.make("ur5e-reach", backend="bullet")
    expected = "mujoco" if jax.default_backend() == "cpu" else "mjx"
    assert envs.make("panda-reach").backend == expected  # the default is "auto"
    assert envs.make("panda-reach", backend="mjx").backend == "mjx"


@pytest.mark.parametrize("name", ARM_ENVS)
def test_native_episode_matches_a_plain_mujoco_loop(pair, name):
    """125 steps of random actions: the env's joint positions and velocities against `mj_step` called
    substeps times per env step with the controls the env applied, in float64 from the same start (N envs: the
    reset compiled for the tests below)."""
    wrapped, reset, _, _ = pair(name)
    env = wrapped.unwrapped
    n, steps = N, 125

    @jax.jit
    def episode(state, key):
        def body(state, k):
            action = jax.random.uniform(k, (n, env.action_size), minval=-1, maxval=1)
            state = wrapped.step(state, action)
            return state, (state.pipeline_state.ctrl, state.pipeline_state.qpos, state.pipeline_state.qvel)
        return jax.lax.scan(body, state, jax.random.split(key, steps))[1]

    start = reset(jax.random.split(_key(3), n))
    ctrls, qpos, qvel = (np.asarray(x) for x in episode(start, _key(4)))
    model = env.robot.mj_model
    tol = EPISODE_TOLERANCE[env.robot.name]
    for i in range(n):
        data = mujoco.MjData(model)
        data.qpos[:] = np.asarray(start.pipeline_state.qpos[i], np.float64)
        for t in range(steps):
            data.ctrl[:] = ctrls[t, i]
            mujoco.mj_step(model, data, nstep=env.config.substeps)
            np.testing.assert_allclose(qpos[t, i], data.qpos, atol=tol, err_msg=f"env {i}, step {t}")
            np.testing.assert_allclose(qvel[t, i], data.qvel, atol=100 * tol, rtol=1e-3, err_msg=f"env {i}, step {t}")
    assert np.ptp(qpos, axis=0).max() > 0.1  # the arms moved


@pytest.mark.parametrize("name", MJX_ENVS)
def test_backends_agree_step_by_step(pair, name):
    """From the same states (the native trajectory), one step on each backend: joint positions,
    collision flags, rewards, observations and metrics agree."""
    native, reset, step, mjx_step = pair(name)
    robot = native.unwrapped.robot
    n, steps = N, 12
    state = reset(jax.random.split(_key(5), n))
    bound = ACTION_BOUND[robot.name]
    for t in range(steps):
        action = jax.random.uniform(_key(100 + t), (n, native.action_size), minval=-bound, maxval=bound)
        a, b = step(state, action), mjx_step(state, action)
        np.testing.assert_allclose(a.pipeline_state.qpos, b.pipeline_state.qpos, atol=2e-5, err_msg=f"step {t}")
        np.testing.assert_allclose(a.pipeline_state.qvel, b.pipeline_state.qvel, atol=2e-3, rtol=1e-3)
        np.testing.assert_allclose(a.reward, b.reward, atol=1e-4)
        np.testing.assert_allclose(a.obs, b.obs, atol=1e-4, rtol=1e-4)
        for metric in ("self_collision", "obstacle_collision", "in_target", "physics_nan"):
            np.testing.assert_array_equal(a.metrics[metric], b.metrics[metric], err_msg=f"{metric}, step {t}")
        state = a
    moved = np.abs(state.pipeline_state.qpos - reset(jax.random.split(_key(5), n)).pipeline_state.qpos).max()
    assert moved > 0.005


@pytest.mark.parametrize("name", MJX_ENVS)
def test_backends_flag_the_same_collisions_from_colliding_configurations(pair, name):
    """Each env jumps into a configuration CPU MuJoCo finds in self-collision and holds it: both
    backends end the episode with a self-collision and the same reward."""
    native, reset, step, mjx_step = pair(name)
    robot = native.unwrapped.robot
    n = N
    state = reset(jax.random.split(_key(6), n))
    q = jnp.stack([colliding_configuration(robot, seed=20 + i) for i in range(n)])
    state = state.replace(pipeline_state=state.pipeline_state.replace(qpos=q, qvel=jnp.zeros_like(q)))
    hold = jnp.zeros((n, native.action_size))  # relative control: hold the pose
    a, b = step(state, hold), mjx_step(state, hold)
    np.testing.assert_array_equal(a.metrics["self_collision"], 1)
    np.testing.assert_array_equal(b.metrics["self_collision"], 1)
    np.testing.assert_array_equal(a.done, b.done)
    np.testing.assert_allclose(a.reward, b.reward, atol=1e-6)


def test_ur5e_difference_is_the_force_clamp():
    """The documented UR5e difference between the backends: with the actuators' force limits lifted (their
    range widened to +-1e9 N m, which no force reaches), MJX and C MuJoCo agree; with them, a large position step
    (clamped forces) makes them differ. The model is an argument of one compiled MJX loop: the range is data."""
    gaps = {}
    loop = jax.jit(lambda mx, d: jax.lax.fori_loop(0, 20, lambda _, d: mjx.step(mx, d), d))
    for limited in (True, False):
        model = envs.make("ur5e-reach", backend="mujoco").robot.mj_model.__copy__()
        assert model.actuator_forcelimited.all()
        if not limited:
            model.actuator_forcerange[:] = [-1e9, 1e9]
        q0 = np.array([0.3, -1.2, 1.0, -0.5, 0.8, 0.1])
        ctrl = q0 + 0.3
        data = mujoco.MjData(model)
        data.qpos[:], data.ctrl[:] = q0, ctrl
        mujoco.mj_step(model, data, nstep=20)
        mx = mjx.put_model(model)
        d = mjx.make_data(mx).replace(qpos=jnp.asarray(q0, jnp.float32), ctrl=jnp.asarray(ctrl, jnp.float32))
        d = loop(mx, d)
        gaps[limited] = float(np.abs(np.asarray(d.qpos) - data.qpos).max())
    assert gaps[False] < 1e-5, gaps
    assert gaps[True] > 1e-3, gaps


def test_native_reports_diverging_physics_as_nan():
    """C MuJoCo resets an env whose accelerations blow up; the backend returns NaN for it, so the env
    ends that episode with physics_nan as it does under MJX."""
    env = envs.make("panda-reach", backend="mujoco")
    physics = env.physics
    nq, nv = physics.nq, physics.nv
    good = np.concatenate([[0.0], np.zeros(nq), np.zeros(nv), np.zeros(nv), np.zeros(env.robot.mj_model.nu)])
    huge = good.copy()
    huge[1 + nq:1 + nq + nv] = 1e12  # velocities C MuJoCo rejects
    nan = good.copy()
    nan[1] = np.nan
    out = physics.host_step(np.stack([good, huge, nan]).astype(np.float32))
    assert np.isfinite(out[0]).all()
    assert np.isnan(out[1]).all()
    assert np.isnan(out[2]).all()
    np.testing.assert_allclose(out[0, 0], physics.substeps * physics.dt, rtol=1e-6)  # time advanced


def test_episode_metrics_of_a_fixed_policy_agree_between_backends(pair):
    """A pseudo-IK policy (relative steps towards the pose that produced the target) runs a UR5e
    episode (80 steps) on each backend from the same start: the episodes' metrics agree. Its large steps clamp
    the UR5e's forces, so the paths differ slightly; both servo to the same pose."""
    native, reset, step, mjx_step = pair("ur5e-reach")
    scale = native.unwrapped.config.action_scale
    start = reset(jax.random.split(_key(8), N))
    ends = {}
    for backend, fn in (("mujoco", step), ("mjx", mjx_step)):
        state = start
        for _ in range(80):
            action = jnp.clip((state.info["target_qpos"] - state.pipeline_state.qpos) / scale, -1.0, 1.0)
            state = fn(state, action)
        ends[backend] = state.metrics
    a, b = ends["mujoco"], ends["mjx"]
    for metric in ("target_reached", "self_collision", "in_target"):
        np.testing.assert_array_equal(a[metric], b[metric], err_msg=metric)
    np.testing.assert_allclose(a["distance_last10"], b["distance_last10"], atol=2e-3)
    np.testing.assert_allclose(a["steps_in_target"], b["steps_in_target"], atol=2)
    # the policy moves the arm a long way towards the target (a collision on the way may end the episode)
    assert float(jnp.min(a["distance"] / start.metrics["distance"])) < 0.6
