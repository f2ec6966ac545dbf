"""Sections 3 and 4 of assets/derive.py: which robot geom pairs can touch, the self-collision rate, the reach.

Kinematics only, so the models load without gravity compensation whatever derive.py's --gravcomp says.
"""
from __future__ import annotations

import time

import mujoco
import numpy as np

from robot_models import joint_limits, load, sample_q, xml_path

# Candidate pairs in contact in the samples that we still leave out, with the reason.
EXCLUDED = {
    "panda": {
        ("link1", "link3"): "capsule artefact: Franka's link3 capsule reaches down to 0.036 m from the joint-2 "
                            "axis, into joint 2's housing (link2, adjacent to link1; cuRobo's mesh-fitted link3 "
                            "spheres start at 0.156 m); it meets link1's capsule only for |joint2| > 1.28 rad. "
                            "MoveIt's panda_moveit_config SRDF disables panda_link1/panda_link3 (reason Default).",
    },
}


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
