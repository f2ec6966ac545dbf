"""The `mujoco` physics backend: the arm's substeps stepped by MuJoCo's C library on the CPU.

Only the physics differs from the `mjx` backend: `ArmEnv` calls `NativePhysics.simulate` from inside its
jitted step through `jax.pure_callback`, and the task logic around it (sampling, the analytic collision
checks after every substep, rewards, observations, auto-reset) is the same JAX code for both backends.
A batch of envs is stepped by `mujoco.rollout` on a pool of C threads (one per CPU core), so on a CPU
no MJX program is compiled and a step costs what MuJoCo's C step costs.

State passed across the callback: time, qpos, qvel (float32 in the env state, float64 in C), the
position targets (ctrl, held for all substeps) and qacc_warmstart. `qacc` is MuJoCo's acceleration of
the last substep (`NativePhysics._last_acceleration`), which also warm-starts the next env step's
solver. The env state keeps MJX's `Data` layout; fields beyond these (actuator forces, constraint
forces) are not updated by this backend. An env whose physics diverges (C MuJoCo then resets its data
and warns) comes back as NaN, which the env reports as `physics_nan`, as MJX's NaN does.
"""

from __future__ import annotations

import os
import threading

import jax
import jax.numpy as jnp
import mujoco
import numpy as np
from mujoco import rollout

_POOL: dict[int, rollout.Rollout] = {}
_POOL_LOCK = threading.Lock()


def num_threads() -> int:
    """C threads stepping a batch: the CPU cores this process may use."""
    try:
        return max(1, len(os.sched_getaffinity(0)))
    except AttributeError:  # not on Linux
        return max(1, os.cpu_count() or 1)


def _pool(nthread: int) -> rollout.Rollout:
    """One thread pool per process (0 threads: steps on the calling thread)."""
    with _POOL_LOCK:
        if nthread not in _POOL:
            _POOL[nthread] = rollout.Rollout(nthread=nthread if nthread > 1 else 0)
        return _POOL[nthread]


class NativePhysics:
    """C MuJoCo stepping of one robot model, `substeps` physics steps per env step."""

    def __init__(self, robot, substeps: int):
        mj_model = robot.mj_model
        self.robot = robot
        self.model = mj_model
        self.substeps = int(substeps)
        self.dt = float(mj_model.opt.timestep)
        self.nq, self.nv = mj_model.nq, mj_model.nv
        self.spec = mujoco.mjtState.mjSTATE_FULLPHYSICS
        if mujoco.mj_stateSize(mj_model, self.spec) != 1 + self.nq + self.nv:
            raise ValueError("the mujoco backend expects a model whose physics state is (time, qpos, qvel): no "
                             "actuator activations, history or plugins.")
        self.nthread = num_threads()
        self._datas = [mujoco.MjData(mj_model) for _ in range(max(1, self.nthread))]
        self._forward = mujoco.MjData(mj_model)
        # One batch at a time: with several JAX devices their callbacks run on concurrent threads, and the
        # MjData scratch above is shared.
        self._lock = threading.Lock()

    # ----------------------------------------------------------------------------------------
    # Inside jit

    def run(self, data, distances):
        """`(data, closest)` after one env step: see `envs.physics.MjxPhysics.run`. The collision checks
        see the configuration at each substep's start (as MJX's geom poses do), from the robot's kinematics."""
        time, path, qvel, qacc = self.simulate(data.time, data.qpos, data.qvel, data.qacc_warmstart, data.ctrl)
        starts = jnp.concatenate([data.qpos[None], path[:-1]])
        kin = self.robot.kinematics(starts)
        closest = jnp.min(jax.vmap(distances)(kin.geom_xpos, kin.geom_xmat, jnp.arange(self.substeps)), axis=0)
        return data.replace(time=time, qpos=path[-1], qvel=qvel, qacc=qacc, qacc_warmstart=qacc), closest

    def simulate(self, time, qpos, qvel, warmstart, ctrl):
        """`(time, qpos_path [substeps, nq], qvel, qacc)` after `substeps` physics steps holding `ctrl`.

        `qpos_path[k]` is the configuration after substep k. Callable under `jit` and `vmap` (any
        number of batch axes reach the C code as one batch). One array each way: every argument of a
        callback costs a conversion on each call."""
        packed = jnp.concatenate([jnp.reshape(time, (1,)), qpos, qvel, warmstart, ctrl]).astype(jnp.float32)
        width = 1 + self.substeps * self.nq + 2 * self.nv
        out = jax.pure_callback(self.host_step, jax.ShapeDtypeStruct((width,), jnp.float32), packed,
                                vmap_method="broadcast_all")
        path_end = 1 + self.substeps * self.nq
        return (out[0], out[1:path_end].reshape(self.substeps, self.nq), out[path_end:path_end + self.nv],
                out[path_end + self.nv:])

    # ----------------------------------------------------------------------------------------
    # On the host

    def host_step(self, packed):
        """numpy version of `simulate` on packed rows [time, qpos, qvel, warmstart, ctrl] with any
        leading batch axes; returns rows [time, qpos_path (flat), qvel, qacc]."""
        nq, nv, nu, S = self.nq, self.nv, self.model.nu, self.substeps
        batch = packed.shape[:-1]
        rows = np.asarray(packed, np.float64).reshape(-1, packed.shape[-1])
        n = len(rows)
        finite = np.all(np.isfinite(rows), axis=1)
        rows = np.where(finite[:, None], rows, 0.0)  # non-finite inputs are not stepped (C MuJoCo would reset them)
        start = rows[:, :1 + nq + nv]
        warm = rows[:, 1 + nq + nv:1 + nq + 2 * nv]
        control = rows[:, None, 1 + nq + 2 * nv:1 + nq + 2 * nv + nu]
        with self._lock:
            states, _ = _pool(self.nthread).rollout(self.model, self._datas, start, control, nstep=S,
                                                    initial_warmstart=warm)
            states = states.reshape(n, S, 1 + nq + nv)
            # C MuJoCo resets an env whose accelerations blow up (time restarts at 0): such envs are NaN.
            expected = start[:, :1] + self.dt * np.arange(1, S + 1)
            ok = finite & np.all(np.abs(states[:, :, 0] - expected) < 0.5 * self.dt, axis=1)
            qacc = self._last_acceleration(states[:, -2] if S > 1 else start, control[:, 0], warm, ok)
        out = np.concatenate([states[:, -1, :1], states[:, :, 1:1 + nq].reshape(n, S * nq),
                              states[:, -1, 1 + nq:], qacc], axis=1)
        out[~ok] = np.nan
        return out.astype(np.float32).reshape(batch + (out.shape[-1],))

    def _last_acceleration(self, before, ctrl, warmstart, ok):
        """qacc of the last substep: a forward pass from the state it started from (MuJoCo's step computes
        qacc there before integrating). The solver's warm start is the env step's, not the previous
        substep's acceleration (rollout does not return it): the same qacc unless a joint-limit
        constraint is active, where the one-iteration Newton solve lands elsewhere (the size of that
        difference: tests/test_native_backend.py, docs/environments.md)."""
        d = self._forward
        out = np.zeros((len(before), self.nv))
        for i in np.flatnonzero(ok):
            mujoco.mj_setState(self.model, d, before[i], self.spec)
            d.ctrl[:] = ctrl[i]
            d.qacc_warmstart[:] = warmstart[i]
            mujoco.mj_forward(self.model, d)
            out[i] = d.qacc
        return out
