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
import pathlib
import time

import mujoco
import numpy as np
from mujoco import rollout

from envs.robots import Panda, UR5e

HERE = pathlib.Path(__file__).resolve().parent

# Official joint velocity limits (rad/s), from the robot classes (their one home).
VMAX = {robot.name: np.array(robot.VELOCITY_LIMITS) for robot in (UR5e, Panda)}
# Candidate pairs in contact in the samples that we still leave out, with the reason.
EXCLUDED = {
    "panda": {
        ("link1", "link3"): "capsule artefact: Franka's link3 capsule reaches down to 0.036 m from the joint-2 "
                            "axis, into joint 2's housing (link2, adjacent to link1; cuRobo's mesh-fitted link3 "
                            "spheres start at 0.156 m); it meets link1's capsule only for |joint2| > 1.28 rad. "
                            "MoveIt's panda_moveit_config SRDF disables panda_link1/panda_link3 (reason Default).",
    },
}
TARGET_FRACTION = 0.92  # aim for peaks at 92 % of the limit: realistic, with margin for unseen poses
CONTROL_SUBSTEPS = 20   # one env step = 20 x 2 ms
GRAVCOMP = False        # set by --gravcomp: every robot body gets gravcomp = 1 (as envs/ can request)


def xml_path(robot: str) -> pathlib.Path:
    return HERE / f"{robot}.xml"


def load(robot: str) -> mujoco.MjModel:
    spec = mujoco.MjSpec.from_file(str(xml_path(robot)))
    if GRAVCOMP:
        for body in spec.bodies:
            if not body.mocap:
                body.gravcomp = 1.0
    return spec.compile()


def joint_limits(m: mujoco.MjModel) -> tuple[np.ndarray, np.ndarray]:
    return m.jnt_range[:, 0].copy(), m.jnt_range[:, 1].copy()


def sample_q(m: mujoco.MjModel, rng: np.random.Generator, n: int) -> np.ndarray:
    lo, hi = joint_limits(m)
    return rng.uniform(lo, hi, size=(n, m.nq))


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


def integrator_section(robot, rng, quick):
    """Stability of the servo's velocity gain kv under Euler (explicit in kv) and implicitfast."""
    print("\n== 2c. Integrator: linearised velocity update v+ = A v around random poses "
          "(unsaturated servo), and holding the zero pose")
    n = 200 if quick else 2000
    for name in ("mjINT_EULER", "mjINT_IMPLICITFAST"):
        m = load(robot)
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


# ------------------------------------------------------------------------------------------------------
# 3. Collision pairs
# ------------------------------------------------------------------------------------------------------
def robot_geoms(m) -> list[int]:
    return [g for g in range(m.ngeom)
            if m.geom_bodyid[g] != 0 and m.body_mocapid[m.geom_bodyid[g]] < 0]


def adjacent(m, g1: int, g2: int) -> bool:
    b1, b2 = m.geom_bodyid[g1], m.geom_bodyid[g2]
    return b1 == b2 or m.body_parentid[b1] == b2 or m.body_parentid[b2] == b1


def candidate_self_pairs(m) -> list[tuple[int, int]]:
    geoms = robot_geoms(m)
    return [(a, b) for i, a in enumerate(geoms) for b in geoms[i + 1:] if not adjacent(m, a, b)]


def with_pairs(robot: str, pairs_by_name, margin: float = 0.0) -> mujoco.MjModel:
    """The model with contacts enabled and exactly `pairs_by_name` as explicit pairs."""
    spec = mujoco.MjSpec.from_file(str(xml_path(robot)))
    spec.option.disableflags &= ~int(mujoco.mjtDisableBit.mjDSBL_CONTACT)
    for p in list(spec.pairs):
        spec.delete(p)
    for n1, n2 in pairs_by_name:
        spec.add_pair(geomname1=n1, geomname2=n2, margin=margin)
    return spec.compile()


def pair_distances(m, d, qs: np.ndarray, pair_index: np.ndarray, npairs: int):
    """Signed distance (capped at the pair margin) of every explicit pair, for every configuration."""
    margin = m.pair_margin.max() if m.npair else 0.0
    out = np.full((len(qs), npairs), margin)
    for i, q in enumerate(qs):
        d.qpos[:] = q
        mujoco.mj_kinematics(m, d)
        mujoco.mj_collision(m, d)
        n = d.ncon
        if n:
            geom = d.contact.geom[:n]
            k = pair_index[geom[:, 0], geom[:, 1]]
            np.minimum.at(out[i], k, d.contact.dist[:n])
    return out


def minimise_distance(m, d, g1, g2, q_starts):
    """Local minimisation (Powell and L-BFGS-B, box-bounded) of the signed distance between two geoms."""
    from scipy.optimize import minimize
    lo, hi = joint_limits(m)

    def dist(q):
        d.qpos[:] = np.clip(q, lo, hi)
        mujoco.mj_kinematics(m, d)
        return mujoco.mj_geomDistance(m, d, g1, g2, 10.0, None)

    best = (np.inf, None)
    for q0 in q_starts:
        for method in ("Powell", "L-BFGS-B"):
            r = minimize(dist, q0, method=method, bounds=list(zip(lo, hi)))
            if r.fun < best[0]:
                best = (float(r.fun), np.clip(r.x, lo, hi))
    return best


def moving_geoms(m, qs: np.ndarray) -> list[int]:
    """Robot geoms whose occupied volume changes with q (a capsule spinning about its own axis does not)."""
    d = mujoco.MjData(m)
    ends = []
    for q in qs:
        d.qpos[:] = q
        mujoco.mj_kinematics(m, d)
        axis = d.geom_xmat.reshape(-1, 3, 3)[:, :, 2] * m.geom_size[:, 1:2]
        ends.append(np.stack([d.geom_xpos - axis, d.geom_xpos + axis], axis=1))
    ends = np.array(ends)                              # (n, ngeom, 2, 3)
    ref = ends[0]
    same = np.minimum(np.abs(ends - ref).max(axis=(2, 3)),
                      np.abs(ends - ref[:, ::-1]).max(axis=(2, 3)))  # endpoints may swap
    return [g for g in robot_geoms(m) if same[:, g].max() > 1e-9]


def pairs_section(robot, rng, quick):
    m0 = load(robot)
    n_samples = 30_000 if quick else 300_000
    cands = candidate_self_pairs(m0)
    gname = lambda g: m0.geom(g).name  # noqa: E731
    names = [(gname(a), gname(b)) for a, b in cands]
    probe_margin = 0.1
    m = with_pairs(robot, names, margin=probe_margin)
    d = mujoco.MjData(m)
    # the compiler sorts pairs by body signature: name them in compiled order
    names = [(m.geom(m.pair_geom1[k]).name, m.geom(m.pair_geom2[k]).name) for k in range(m.npair)]
    pair_index = np.full((m.ngeom, m.ngeom), -1)
    for k in range(m.npair):
        pair_index[m.pair_geom1[k], m.pair_geom2[k]] = pair_index[m.pair_geom2[k], m.pair_geom1[k]] = k

    t0 = time.time()
    qs = sample_q(m, rng, n_samples)
    dist = pair_distances(m, d, qs, pair_index, m.npair)
    hit = dist < 0
    counts = hit.sum(axis=0)
    print(f"\n== 3a. Self pairs: {len(cands)} candidates (different, non-adjacent bodies), "
          f"{n_samples} uniform configurations, {time.time() - t0:.1f} s")
    print(f"  {'pair':32s} {'in contact':>10s} {'fraction':>9s} {'min dist':>9s}  decision")
    keep, notes = [], {}
    excluded = EXCLUDED.get(robot, {})
    for k, (n1, n2) in enumerate(names):
        decision = "keep" if counts[k] else "prune"
        extra = ""
        if (n1, n2) in excluded:
            decision = "EXCLUDE (see below)"
        if counts[k] == 0 and dist[:, k].min() < probe_margin:
            starts = qs[np.argsort(dist[:, k])[:4 if quick else 16]]
            best, q_best = minimise_distance(m, d, m0.geom(n1).id, m0.geom(n2).id, starts)
            extra = f"; local minimum {best:+.4f} m"
            if best < 0:
                decision = "keep (found by minimisation)"
                notes[(n1, n2)] = q_best
        if decision.startswith("keep"):
            keep.append((n1, n2))
        mind = dist[:, k].min()
        mind_s = f"{mind:+.4f}" if mind < probe_margin else f">{probe_margin:.2f}"
        print(f"  {n1 + ' - ' + n2:32s} {counts[k]:10d} {counts[k] / n_samples:9.2e} {mind_s:>9s}  "
              f"{decision}{extra}")
    for pair, q in notes.items():
        print(f"  witness for {pair}: qpos {np.round(q, 4).tolist()}")
    for pair, reason in excluded.items():
        print(f"  excluded {pair[0]} - {pair[1]}: {reason}")
    kept_counts = [counts[names.index(p)] for p in keep]
    if kept_counts:
        k_min = int(np.argmin(kept_counts))
        print(f"  kept {len(keep)} of {len(cands)}; smallest kept count {kept_counts[k_min]} "
              f"({keep[k_min][0]} - {keep[k_min][1]})")

    kept_idx = [names.index(p) for p in keep]

    frac = hit[:, kept_idx].any(axis=1).mean()
    print(f"\n== 4a. Self-collision: {frac:.2%} of uniform full-range configurations "
          f"({hit[:, kept_idx].any(axis=1).sum()} of {n_samples}) collide on a kept pair")
    print(f"  with a 0.02 m safety margin: {(dist[:, kept_idx] < 0.02).any(axis=1).mean():.2%}")
    if excluded:
        ex_idx = kept_idx + [names.index(p) for p in excluded]
        print(f"  counting the excluded pairs too: {hit[:, ex_idx].any(axis=1).mean():.2%}")
    home = load(robot).key("home").qpos
    home_d = pair_distances(m, d, home[None], pair_index, m.npair)[0]
    print(f"  home keyframe: closest kept pair {names[kept_idx[np.argmin(home_d[kept_idx])]]} at "
          f"{home_d[kept_idx].min():+.4f} m (capped at the probe margin {probe_margin} m)")

    movers = moving_geoms(m0, qs[:2000])
    static = [gname(g) for g in robot_geoms(m0) if g not in movers]
    print(f"\n== 3b. Obstacle pairs: {len(movers)} moving robot geoms; static or spinning in place "
          f"(cannot newly meet a static obstacle): {static}")

    print("\n== 3c. <contact> block")
    print("  <contact>")
    for n1, n2 in keep:
        print(f'    <pair geom1="{n1}" geom2="{n2}"/>')
    for g in movers:
        print(f'    <pair geom1="{gname(g)}" geom2="obstacle"/>')
    print("  </contact>")
    return qs


# ------------------------------------------------------------------------------------------------------
# 4. Reach
# ------------------------------------------------------------------------------------------------------
def shoulder_point(m) -> np.ndarray:
    """Where joint 2's axis meets joint 1's (fixed in the world: the centre of the reachable sphere)."""
    d = mujoco.MjData(m)
    mujoco.mj_kinematics(m, d)
    mujoco.mj_comPos(m, d)
    p1, a1 = d.xanchor[0], d.xaxis[0]
    p2, a2 = d.xanchor[1], d.xaxis[1]
    # closest points of the two axis lines
    w = p1 - p2
    b = a1 @ a2
    s = (b * (a2 @ w) - (a1 @ w)) / (1 - b * b)
    t = ((a2 @ w) - b * (a1 @ w)) / (1 - b * b)
    c1, c2 = p1 + s * a1, p2 + t * a2
    assert np.linalg.norm(c1 - c2) < 1e-6, "joint 1 and 2 axes do not intersect"
    return c1


def reach_section(robot, qs):
    m = load(robot)
    d = mujoco.MjData(m)
    sp = shoulder_point(m)
    sid = m.site("ee").id
    r = np.empty(len(qs))
    for i, q in enumerate(qs):
        d.qpos[:] = q
        mujoco.mj_kinematics(m, d)
        r[i] = np.linalg.norm(d.site_xpos[sid] - sp)
    mujoco.mj_resetDataKeyframe(m, d, m.key("home").id)
    mujoco.mj_kinematics(m, d)
    print(f"\n== 4b. Reach: shoulder point (joint-1/joint-2 axes) at world {np.round(sp, 4).tolist()}")
    print(f"  |ee - shoulder| over {len(qs)} uniform configurations: max {r.max():.4f} m, "
          f"99.9th percentile {np.percentile(r, 99.9):.4f} m, median {np.median(r):.4f} m")
    print(f"  ee at home: {np.round(d.site_xpos[sid], 4).tolist()}")


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
    global GRAVCOMP
    GRAVCOMP = args.gravcomp
    # one independent stream per section, so that each section's numbers do not depend on the others
    rngs = [np.random.default_rng([args.seed, k]) for k in range(4)]
    m = load(args.robot)
    print(f"# {args.robot}: {xml_path(args.robot).name}, MuJoCo {mujoco.__version__}, seed {args.seed}"
          f"{', quick' if args.quick else ''}{', gravity compensation' if args.gravcomp else ''}")
    if args.robot == "panda":
        hand_inertia()
    velocity_section(m, args.robot, rngs[0], args.quick, args.tune)
    settle_section(load(args.robot), args.robot, rngs[1], args.quick)
    integrator_section(args.robot, rngs[2], args.quick)
    qs = pairs_section(args.robot, rngs[3], args.quick)
    reach_section(args.robot, qs)


if __name__ == "__main__":
    main()
