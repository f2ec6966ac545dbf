"""Evidence for the robot models in assets/: joint damping, collision pairs, self-collision rate, reach.

    python assets/derive.py [ur5e|panda] [--quick] [--tune] [--gravcomp] [--seed N]

Sections, in the order printed (all on CPU MuJoCo, seeded, a few seconds each):
  1. velocity check: full-range step commands (ctrl jumps from one end of a joint's range to the other and
     is held), each joint alone in worst-case gravity poses and all joints at once; peak |qvel| per joint
     against the official limit. `--tune` first rescales each joint's damping until that peak is
     TARGET_FRACTION of the limit (peak ~ (torque limit + gravity) / damping while the servo saturates).
  2. settling onto a held target under gravity, random ctrl sequences (new uniform ctrl every 40 ms), and
     the stability of the servo's velocity gain under the Euler and implicitfast integrators.
  3. collision pairs: every non-adjacent robot geom pair is enabled, uniformly random joint configurations
     are sampled over the full ranges, and each pair's contact count and closest distance are recorded;
     pairs never seen in contact get a local minimisation of their distance. Prints the <contact> block.
  4. fraction of random configurations in self-collision (kept pairs), reach from the shoulder point.
"""
from __future__ import annotations

import argparse

import mujoco
import numpy as np
from mujoco import rollout

from collision_pairs import pairs_section, reach_section  # sibling modules: this file runs as a script
from envs.robots import Panda, UR5e
from robot_models import joint_limits, load, sample_q, xml_path

# Official joint velocity limits (rad/s), from the robot classes (their one home).
VMAX = {robot.name: np.array(robot.VELOCITY_LIMITS) for robot in (UR5e, Panda)}
TARGET_FRACTION = 0.92  # aim for peaks at 92 % of the limit: realistic, with margin for unseen poses
CONTROL_SUBSTEPS = 20   # one env step = 20 x 2 ms


# ------------------------------------------------------------------------------------------------------
# 1. Velocity under full-range steps
# ------------------------------------------------------------------------------------------------------
def gravity_torque(m, d, q) -> np.ndarray:
    d.qpos[:] = q
    d.qvel[:] = 0
    mujoco.mj_forward(m, d)
    return d.qfrc_bias.copy()


def worst_gravity_pose(m, j: int, rng, n_samples: int = 300, n_grid: int = 24) -> np.ndarray:
    """Pose of the other joints that maximises the largest gravity torque on joint j along its sweep."""
    d = mujoco.MjData(m)
    lo, hi = joint_limits(m)
    sweep = np.linspace(lo[j], hi[j], n_grid)
    best, best_pose = -1.0, None
    for q in sample_q(m, rng, n_samples):
        g = 0.0
        for qj in sweep:
            q[j] = qj
            g = max(g, abs(gravity_torque(m, d, q)[j]))
        if g > best:
            best, best_pose = g, q.copy()
    return best_pose


def step_scenarios(m, robot: str, rng, quick: bool):
    """(label, initial qpos, held ctrl) for the full-range step tests."""
    lo, hi = joint_limits(m)
    home = m.key("home").qpos.copy()
    zero = np.clip(np.zeros(m.nq), lo, hi)
    scenarios = []
    for j in range(m.nq):
        poses = {"home": home, "zero": zero,
                 "worst-gravity": worst_gravity_pose(m, j, rng, 60 if quick else 300)}
        for pose_name, pose in poses.items():
            for a, b, arrow in ((lo[j], hi[j], "lo->hi"), (hi[j], lo[j], "hi->lo")):
                q0, u = pose.copy(), pose.copy()
                q0[j], u[j] = a, b
                scenarios.append((f"joint {j + 1} alone {arrow}, others {pose_name}", q0, u))
    # All joints at once, every combination of directions (2^n; 16 random ones with --quick).
    patterns = [np.array([(k >> j) & 1 for j in range(m.nq)], bool) for k in range(2 ** m.nq)]
    if quick:
        patterns = [patterns[k] for k in rng.choice(len(patterns), 16, replace=False)]
    for up in patterns:
        label = "".join("+" if u else "-" for u in up)
        scenarios.append((f"all joints at once, directions {label}", np.where(up, lo, hi), np.where(up, hi, lo)))
    return scenarios


def simulate_held_ctrl(m, q0s: np.ndarray, ctrls: np.ndarray, seconds: float):
    """Rolls out every (q0, ctrl) pair with ctrl held; returns qpos, qvel of shape (batch, steps, nq)."""
    d = mujoco.MjData(m)
    spec = mujoco.mjtState.mjSTATE_FULLPHYSICS
    states = []
    for q0 in q0s:
        mujoco.mj_resetData(m, d)
        d.qpos[:] = q0
        states.append(np.empty(mujoco.mj_stateSize(m, spec)))
        mujoco.mj_getState(m, d, states[-1], spec)
    nstep = int(round(seconds / m.opt.timestep))
    state, _ = rollout.rollout(m, [mujoco.MjData(m) for _ in range(2)], np.array(states),
                               ctrls[:, None, :], nstep=nstep)
    qpos = state[:, :, 1:1 + m.nq]
    qvel = state[:, :, 1 + m.nq:1 + m.nq + m.nv]
    return qpos, qvel


def step_seconds(m, vmax) -> float:
    """Long enough for the slowest full-range move (against gravity at ~40 % of the limit) to finish."""
    lo, hi = joint_limits(m)
    return float(np.max((hi - lo) / (0.4 * vmax))) + 1.0


def peak_speeds(m, scenarios, vmax):
    q0s = np.array([s[1] for s in scenarios])
    ctrls = np.array([s[2] for s in scenarios])
    _, qvel = simulate_held_ctrl(m, q0s, ctrls, step_seconds(m, vmax))
    if not np.all(np.isfinite(qvel)):
        raise RuntimeError("non-finite velocity in a step scenario")
    per_scen = np.abs(qvel).max(axis=1)          # (batch, nv)
    return per_scen.max(axis=0), per_scen.argmax(axis=0)


def tune_damping(m, scenarios, vmax, iters: int = 8):
    """Fixed-point rescaling: while saturated, peak speed ~ (torque limit + gravity) / damping."""
    for it in range(iters):
        peaks, _ = peak_speeds(m, scenarios, vmax)
        ratio = peaks / (TARGET_FRACTION * vmax)
        print(f"  iter {it}: damping {np.round(m.dof_damping, 2)}  peak/limit {np.round(peaks / vmax, 3)}")
        m.dof_damping[:] = m.dof_damping * ratio
        if np.max(np.abs(ratio - 1)) < 0.003:
            break
    m.dof_damping[:] = np.round(m.dof_damping, 1)
    return m.dof_damping.copy()


def velocity_section(m, robot, rng, quick, tune):
    vmax = VMAX[robot]
    scenarios = step_scenarios(m, robot, rng, quick)
    print(f"\n== 1. Full-range step commands ({len(scenarios)} scenarios, ctrl held, "
          f"{step_seconds(m, vmax):.1f} s each)")
    if tune:
        print(f"  tuning damping to {TARGET_FRACTION:.0%} of the limit:")
        tuned = tune_damping(m, scenarios, vmax)
        print("  tuned damping (paste into the XML):", ", ".join(f"{x:.1f}" for x in tuned))
    peaks, which = peak_speeds(m, scenarios, vmax)
    names = [m.joint(j).name for j in range(m.njnt)]
    print(f"  {'joint':22s} {'damping':>8s} {'peak':>7s} {'limit':>7s} {'ratio':>6s}  worst scenario")
    for j in range(m.nv):
        print(f"  {names[j]:22s} {m.dof_damping[j]:8.1f} {peaks[j]:7.3f} {vmax[j]:7.3f} "
              f"{peaks[j] / vmax[j]:6.1%}  {scenarios[which[j]][0]}")
    # Hand check: a saturated servo with no gravity or coupling settles at torque limit / damping.
    frc = m.actuator_forcerange[:, 1]
    print("  torque limit / damping (one joint alone, no gravity), share of the limit: "
          + ", ".join(f"{f / dmp:.2f} ({f / dmp / v:.0%})" for f, dmp, v in zip(frc, m.dof_damping, vmax)))
    ok = np.all(peaks <= vmax)
    print(f"  all peaks within the official limits: {ok}")
    return peaks


# ------------------------------------------------------------------------------------------------------
# 2. Settling and random ctrl
# ------------------------------------------------------------------------------------------------------
def settle_section(m, robot, rng, quick):
    print("\n== 2a. Settling onto a held target (ctrl held, gravity on)")
    lo, hi = joint_limits(m)
    home = m.key("home").qpos.copy()
    zero = np.clip(np.zeros(m.nq), lo, hi)
    step = np.clip(home + 0.5, lo, hi)
    cases = [("hold the zero pose (max gravity load)", zero, zero),
             ("hold home", home, home),
             ("home -> home + 0.5 rad on every joint", home, step)]
    qpos, qvel = simulate_held_ctrl(m, np.array([c[1] for c in cases]), np.array([c[2] for c in cases]), 4.0)
    dt = m.opt.timestep
    for (label, q0, u), qp, qv in zip(cases, qpos, qvel):
        final = qp[-1]
        err = np.abs(qp - final).max(axis=1)
        t_settle = []
        for tol in (1e-2, 1e-3):
            outside = np.nonzero(err > tol)[0]
            t_settle.append((outside[-1] + 1) * dt if len(outside) else 0.0)
        print(f"  {label}: within 10 / 1 mrad of rest after {t_settle[0]:.2f} / {t_settle[1]:.2f} s; "
              f"rest - ctrl (rad) {np.round(final - u, 4)}; |qvel| at 4 s {np.abs(qv[-1]).max():.1e}")
    # Explicit Euler treats the servo's kv explicitly; measure step-to-step velocity chatter after a step.
    qv = qvel[2]
    dv = np.diff(qv, axis=0)
    flips = (dv[1:] * dv[:-1] < 0) & (np.abs(dv[1:]) > 1e-3)
    print(f"  velocity-increment sign flips > 1e-3 rad/s per step (chatter), per joint: {flips.sum(axis=0)}")

    n_env, seconds = (4, 4.0) if quick else (16, 10.0)
    print(f"\n== 2b. Random ctrl: {n_env} runs x {seconds:.0f} s, new uniform ctrl every "
          f"{CONTROL_SUBSTEPS * dt * 1e3:.0f} ms, random start")
    vmax = VMAX[robot]
    d = mujoco.MjData(m)
    worst_v = np.zeros(m.nv)
    above = np.zeros(m.nv)
    worst_out = 0.0
    bad = 0
    for _ in range(n_env):
        mujoco.mj_resetData(m, d)
        d.qpos[:] = sample_q(m, rng, 1)[0]
        for k in range(int(seconds / dt)):
            if k % CONTROL_SUBSTEPS == 0:
                d.ctrl[:] = rng.uniform(m.actuator_ctrlrange[:, 0], m.actuator_ctrlrange[:, 1])
            mujoco.mj_step(m, d)
            worst_v = np.maximum(worst_v, np.abs(d.qvel))
            above += np.abs(d.qvel) > vmax
            worst_out = max(worst_out, float(np.max(np.maximum(lo - d.qpos, d.qpos - hi))))
        bad += int(sum(d.warning[i].number for i in range(len(d.warning))))
        if not np.all(np.isfinite(d.qpos)):
            bad += 1
    print(f"  non-finite states / MuJoCo warnings: {bad}")
    print(f"  peak |qvel| / limit per joint: {np.round(worst_v / vmax, 3)}")
    print(f"  share of time above the limit per joint: {np.round(above / (n_env * int(seconds / dt)), 4)}")
    print(f"  largest excursion beyond a joint limit: {max(worst_out, 0.0):.4f} rad")


def integrator_section(robot, rng, quick, gravcomp):
    """Stability of the servo's velocity gain kv under Euler (explicit in kv) and implicitfast."""
    print("\n== 2c. Integrator: linearised velocity update v+ = A v around random poses "
          "(unsaturated servo), and holding the zero pose")
    n = 200 if quick else 2000
    for name in ("mjINT_EULER", "mjINT_IMPLICITFAST"):
        m = load(robot, gravcomp)
        in_file = m.opt.integrator == getattr(mujoco.mjtIntegrator, name)
        m.opt.integrator = getattr(mujoco.mjtIntegrator, name)
        d = mujoco.MjData(m)
        h, damp = m.opt.timestep, np.diag(m.dof_damping)
        kv = np.zeros((m.nv, m.nv))
        kv[m.actuator_trnid[:, 0], m.actuator_trnid[:, 0]] = -m.actuator_biasprm[:, 2]
        radius = []
        for q in sample_q(m, rng, n):
            d.qpos[:] = q
            mujoco.mj_forward(m, d)
            mass = np.zeros((m.nv, m.nv))
            mujoco.mj_fullM(m, d, mass)
            if name == "mjINT_EULER":   # damping implicit, kv explicit
                a = np.linalg.solve(mass + h * damp, mass - h * kv)
            else:                       # both implicit
                a = np.linalg.solve(mass + h * (damp + kv), mass)
            radius.append(np.abs(np.linalg.eigvals(a)).max())
        radius = np.array(radius)
        zero = np.clip(np.zeros(m.nq), *joint_limits(m))
        _, qvel = simulate_held_ctrl(m, zero[None], zero[None], 3.0)
        late = np.abs(qvel[0, -250:]).max(axis=0)
        print(f"  {name[6:].lower():12s}{' (this file)' if in_file else '            '}: spectral radius max "
              f"{radius.max():.3f}, > 1 in {np.mean(radius > 1):.1%} of {n} poses; holding the zero pose, "
              f"max |qvel| over the last 0.5 s {np.round(late, 3)}")


def hand_inertia():
    """Panda: Menagerie hand inertial plus both (closed) fingers, by the parallel-axis theorem."""
    def about(mass, com, inertia, point):
        r = np.asarray(com) - point
        return inertia + mass * (r @ r * np.eye(3) - np.outer(r, r))
    parts = [(0.73, np.array([-0.01, 0, 0.03]), np.diag([0.001, 0.0025, 0.0017]))] + \
        [(0.015, np.array([0, 0, 0.0584]), np.diag([2.375e-6, 2.375e-6, 7.5e-7]))] * 2
    mass = sum(p[0] for p in parts)
    com = sum(p[0] * p[1] for p in parts) / mass
    inertia = sum(about(*p, com) for p in parts)
    print(f"\n== 0. Hand + fingers inertial: mass {mass:.3f}, pos {np.round(com, 7).tolist()}, fullinertia "
          f"{inertia[0, 0]:.6g} {inertia[1, 1]:.6g} {inertia[2, 2]:.6g} {inertia[0, 1]:.5g} "
          f"{inertia[0, 2]:.5g} {inertia[1, 2]:.5g}")


def main():
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("robot", nargs="?", default="ur5e", choices=sorted(VMAX))
    ap.add_argument("--quick", action="store_true", help="fewer scenarios and samples (~10x faster)")
    ap.add_argument("--tune", action="store_true", help="re-tune joint damping before the check")
    ap.add_argument("--gravcomp", action="store_true",
                    help="evaluate (or --tune) with passive gravity compensation on every robot body")
    ap.add_argument("--seed", type=int, default=0)
    args = ap.parse_args()
    # one independent stream per section, so that each section's numbers do not depend on the others
    rngs = [np.random.default_rng([args.seed, k]) for k in range(4)]
    m = load(args.robot, args.gravcomp)
    print(f"# {args.robot}: {xml_path(args.robot).name}, MuJoCo {mujoco.__version__}, seed {args.seed}"
          f"{', quick' if args.quick else ''}{', gravity compensation' if args.gravcomp else ''}")
    if args.robot == "panda":
        hand_inertia()
    velocity_section(m, args.robot, rngs[0], args.quick, args.tune)
    settle_section(load(args.robot, args.gravcomp), args.robot, rngs[1], args.quick)
    integrator_section(args.robot, rngs[2], args.quick, args.gravcomp)
    qs = pairs_section(args.robot, rngs[3], args.quick)
    reach_section(args.robot, qs)


if __name__ == "__main__":
    main()
