"""envs.fast_mjx: the GPU replacements of MJX pieces compute what MJX computes.

The Cholesky functions are checked against NumPy's LAPACK, the unrolled loop against MJX's own
bounded loop, and a Panda rollout that runs into joint limits (so the constraint solver and its line
search do real work) against the same rollout with MJX as shipped. The replacements are off on a
CPU by default, so these tests switch them on explicitly.
"""

import jax
import jax.numpy as jnp
import jax.scipy.linalg
import numpy as np
import pytest
from mujoco import mjx
from mujoco.mjx._src import solver as mjx_solver

import envs
from envs import fast_mjx


def _spd(rng, batch, n):
    a = rng.normal(size=batch + (n, n))
    return (a @ np.swapaxes(a, -1, -2) + n * np.eye(n)).astype(np.float32)


@pytest.mark.parametrize("n", [1, 2, 6, 7])
def test_cholesky_matches_lapack(n):
    a = _spd(np.random.default_rng(n), (5,), n)
    factor = np.asarray(fast_mjx.cholesky_lower(jnp.asarray(a)))
    np.testing.assert_allclose(factor, np.linalg.cholesky(a.astype(np.float64)), atol=2e-6)
    assert np.all(np.triu(factor, 1) == 0)


@pytest.mark.parametrize("lower", [False, True])
def test_cho_solve_vector_and_matrix(lower):
    rng = np.random.default_rng(1)
    a = _spd(rng, (), 6)
    c = fast_mjx.cho_factor(a, lower=lower)
    assert c[1] is lower
    # the factor sits in the requested triangle
    u = np.asarray(c[0])
    np.testing.assert_allclose((u @ u.T) if lower else (u.T @ u), a, rtol=1e-5, atol=1e-5)
    b, bm = rng.normal(size=6).astype(np.float32), rng.normal(size=(6, 3)).astype(np.float32)
    np.testing.assert_allclose(fast_mjx.cho_solve(c, b), np.linalg.solve(a, b), atol=1e-5)
    np.testing.assert_allclose(fast_mjx.cho_solve(c, bm), np.linalg.solve(a, bm), atol=1e-5)
    # under vmap, as MJX calls it per environment
    batch = _spd(rng, (4,), 6)
    rhs = rng.normal(size=(4, 6)).astype(np.float32)
    x = jax.vmap(lambda m, v: fast_mjx.cho_solve(fast_mjx.cho_factor(m), v))(batch, rhs)
    np.testing.assert_allclose(x, np.linalg.solve(batch, rhs[..., None])[..., 0], atol=1e-5)


def test_large_matrices_keep_the_library_path():
    n = fast_mjx.MAX_SIZE + 1
    a = _spd(np.random.default_rng(2), (), n)
    b = np.ones(n, np.float32)
    np.testing.assert_allclose(fast_mjx.cho_solve(fast_mjx.cho_factor(a), b), np.linalg.solve(a, b), rtol=1e-4)


def test_unrolled_loop_matches_mjx_loop():
    cond = lambda v: v[0] < 3.5  # stops after 4 of the 6 allowed steps for this start
    body = lambda v: (v[0] + 1.0, v[1] * 2.0 + v[0])
    start = (jnp.float32(0.0), jnp.float32(1.0))
    ours = fast_mjx.unrolled_while_loop_scan(cond, body, start, 6)
    theirs = mjx_solver._while_loop_scan(cond, body, start, 6)
    assert [float(x) for x in ours] == [float(x) for x in theirs] == [4.0, 27.0]
    # a loop that never stops early runs exactly max_iter steps
    ours = fast_mjx.unrolled_while_loop_scan(lambda v: True, body, start, 3)
    assert [float(x) for x in ours] == [3.0, 12.0]


def test_context_restores_what_it_replaced():
    originals = jax.scipy.linalg.cho_factor, jax.scipy.linalg.cho_solve, mjx_solver._while_loop_scan
    with pytest.raises(RuntimeError):
        with fast_mjx.fast_mjx(True):
            assert jax.scipy.linalg.cho_factor is fast_mjx.cho_factor
            assert mjx_solver._while_loop_scan is fast_mjx.unrolled_while_loop_scan
            with fast_mjx.fast_mjx(True):  # re-entrant
                pass
            assert jax.scipy.linalg.cho_solve is fast_mjx.cho_solve
            raise RuntimeError("leave by an exception")
    assert (jax.scipy.linalg.cho_factor, jax.scipy.linalg.cho_solve, mjx_solver._while_loop_scan) == originals
    with fast_mjx.fast_mjx(False):
        assert jax.scipy.linalg.cho_factor is originals[0]


def test_contexts_closed_out_of_order_keep_the_replacements_until_the_last():
    """Two threads' contexts: A opens, B opens, A closes (B still traces with the replacements), B closes."""
    originals = jax.scipy.linalg.cho_factor, jax.scipy.linalg.cho_solve, mjx_solver._while_loop_scan
    first, second = fast_mjx.fast_mjx(True), fast_mjx.fast_mjx(True)
    first.__enter__()
    second.__enter__()
    first.__exit__(None, None, None)
    assert fast_mjx.active()
    second.__exit__(None, None, None)
    assert (jax.scipy.linalg.cho_factor, jax.scipy.linalg.cho_solve, mjx_solver._while_loop_scan) == originals


def test_panda_rollout_into_joint_limits_matches_mjx():
    """20 `mjx.step`s of 8 Panda states (2 ms each, the model's Newton solver and 6-step line search), with and
    without the replacements. MJX's step alone, not the env's: the env adds nothing the replacements touch, and
    compiling it twice on a CPU costs minutes."""
    robot = envs.make("panda-reach", backend="mjx").robot
    model = robot.mjx_model
    low, high = jnp.asarray(robot.joint_low), jnp.asarray(robot.joint_high)
    # Start 0.02 rad beyond a joint limit (upper for half the states, lower for the others), so the
    # constraint solver and its line search push back from the first step.
    beyond = jnp.where((jnp.arange(8) % 2 == 0)[:, None], high + 0.02, low - 0.02)
    start = jax.vmap(lambda q: robot.data_template.replace(qpos=q, ctrl=q))(beyond)
    noise = jax.random.uniform(jax.random.PRNGKey(1), (20, 8, robot.nq), minval=-1.0, maxval=1.0)
    ctrls = jnp.clip(beyond + noise, low, high)

    def rollout(data, ctrls):
        def step(data, ctrl):
            data = jax.vmap(lambda d, c: mjx.step(model, d.replace(ctrl=c)))(data, ctrl)
            return data, (data.qpos, data.qfrc_constraint)
        return jax.lax.scan(step, data, ctrls)[1]

    with fast_mjx.fast_mjx(True):
        fast_program = jax.jit(rollout).lower(start, ctrls)
    shipped_program = jax.jit(lambda d, c: rollout(d, c)).lower(start, ctrls)  # a new function: traced again
    assert "cholesky" in shipped_program.as_text()  # MJX factorises with the library call ...
    assert "cholesky" not in fast_program.as_text()  # ... which the replacement writes out
    fast, shipped = fast_program.compile()(start, ctrls), shipped_program.compile()(start, ctrls)
    assert float(jnp.max(jnp.abs(shipped[1]))) > 1.0  # the limits did push back
    np.testing.assert_allclose(fast[0], shipped[0], atol=1e-5)
    # constraint forces of up to ~500 N agree to float32 rounding of the solve
    np.testing.assert_allclose(fast[1], shipped[1], atol=1e-5 * float(jnp.max(jnp.abs(shipped[1]))))
