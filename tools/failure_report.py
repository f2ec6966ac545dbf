"""Why a policy fails: which links collide, when, from which start, and how far the misses end.

    python -m tools.failure_report --checkpoint results/checkpoints/ur5e-reach-ppo --num-envs 256
    python -m tools.failure_report --checkpoint RUN --env ur5e-reach-avoid --unit 2 --json report.json --plot report.png
    python -m tools.failure_report --from-json report.json --plot report.png      # the picture of a saved report
    python -m tools.failure_report --checkpoint RUN --env.obstacle-speed-range 0 0   # the obstacles held still

Runs one episode per env with the deterministic policy of one trained seed (`--unit`, an index into
the checkpoint's seeds) through `agents.evaluation.rollout`, on the checkpoint's env config with eval.py's
`--env.<field> VALUE` options replacing fields, and sorts every episode into one outcome:
target reached, self collision, obstacle collision, or missed (neither). For collisions it names the
geom pair that is closest (most penetrating) at the end of the colliding step, the step, and the
start pose's clearance (its smallest self-collision distance); for misses the final distance.
Every episode also lists the joints that end it at a range limit (a UR5e joint that turns 720° can
pin there: reaching on may need a full turn back the other way) and, with obstacles (one or several,
static or moving, each where it is at that step), whether the straight line from the end effector to
the target crosses an obstacle's sphere at the start and, for misses, at the end (`obstacle_between`:
an obstacle in the end effector's way), and how close the robot's geoms end to the nearest obstacle's
surface (`final_obstacle_clearance`). An obstacle collision also records whose motion over its last
`APPROACH_STEPS` steps brought the contact (`approach`): the arm's alone, the obstacle's alone, either alone,
or only both together (each asked by holding the other where it was; `approach_clearances` holds the two
clearances; a collision within the first `APPROACH_STEPS` steps is asked from the reset), and how many steps
the end effector had been in the target before it (`steps_in_target`: a colliding step never counts as in the
target; > 0 when the arm was hit after reaching) and whether it was in the target on the step before
(`in_target_before`), and what the paper's link distance read on the step the colliding action was chosen from
(`origin_distance_before`: the nearest link frame origin's distance to an obstacle surface, which the observation
`link_obstacle_dist` gives with `link_distance="origin"`; a contact along a long link can sit far from every origin)
beside the robot's true clearance then (`surface_distance_before`).
Outcomes are also binned by the target's height above the robot's mounting plane (`by_target_height`), and each
episode records how far its end effector starts from the target (`start_distance`), how far it moved
over the episode's last `END_STEPS` steps (`end_motion`: near 0 when the arm has stopped) and the
smallest distance of any joint to its range limit at the end (`joint_margin`).
A CPU handles a few hundred episodes in minutes (UR5e); the Panda is slow on CPUs (README).
"""

from __future__ import annotations

import argparse
import collections
import dataclasses
import json

import numpy as np
import tyro

from tools import run_cli

MISS_BINS = (0.02, 0.05, 0.10)
"""Upper edges (m) of the final-distance bins of missed episodes; the last bin is open."""
LIMIT_MARGIN = 0.05
"""A joint within this many radians of either end of its range counts as at its limit."""
END_STEPS = 10
"""Steps at the end of an episode over which `end_motion` measures the end effector's displacement."""
NEAR_LIMIT = 0.5
"""Joint margin (rad) reported as near a limit when the env's config has none: the default
`joint_limit_margin`, where the env's joint-limit penalty (`w_joint_limit`) starts; `main` passes the
evaluated config's own."""
HEIGHT_BINS = (0.0, 0.1, 0.3, 0.5)
"""Edges (m) of the target-height bins (height above the robot's mounting plane z = 0); the outer
bins are open."""
APPROACH_STEPS = 10
"""Steps before an obstacle collision over which `approach` asks whose motion brought the contact (0.4 s at the
arms' 25 Hz control; from the reset for a collision within the first APPROACH_STEPS steps)."""
PROXIMITY = 0.1
"""Clearance (m) under which the robot counts as near the obstacle: the default `obstacle_tau` of the
paper's proximity penalty (eq. 3; the env measures it from the link origins, `link_distance`)."""


def _names(robot, geoms) -> list[str]:
    return [robot.mj_model.geom(int(g)).name for g in geoms]


def classify(robot, records: dict, obstacle_radius: float | None = None, geoms=None,
             target_radius: float | None = None) -> list[dict]:
    """One dict per env: outcome, step (episode length), start pose's self-collision clearance and, by outcome, the
    colliding pair / geom or the final distance. `records` as `evaluation.rollout` returns them;
    with obstacles in them and their radii (`obstacle_radius`, or recorded per episode), also whether
    one lies between the end effector and the target at the start (and, for misses, at the end).
    `geoms`: the robot geoms the env checks against obstacles (its `checked_geoms`; default the model's
    obstacle pairs). With `target_radius` (m), an obstacle collision also tells whether the end effector was in the
    target on the step before it (`in_target_before`)."""
    import jax
    import jax.numpy as jnp

    from envs import collision

    geoms = robot.obstacle_geoms if geoms is None else geoms
    metrics = records["metrics"]
    qpos = np.asarray(records["qpos"])
    length = np.asarray(records["length"]).astype(int)
    n = qpos.shape[1]
    end_q = qpos[np.minimum(length, qpos.shape[0] - 1), np.arange(n)]
    kin_start, kin_end = robot.kinematics(jnp.asarray(qpos[0])), robot.kinematics(jnp.asarray(end_q))
    before_end = robot.kinematics(jnp.asarray(qpos[np.clip(length - END_STEPS, 0, qpos.shape[0] - 1), np.arange(n)]))
    end_motion = np.linalg.norm(np.asarray(kin_end.ee_pos) - np.asarray(before_end.ee_pos), axis=-1)
    self_start = np.asarray(robot.self_distances(kin_start.geom_xpos, kin_start.geom_xmat))
    self_end = np.asarray(robot.self_distances(kin_end.geom_xpos, kin_end.geom_xmat))
    between = "obstacle_pos" in records and (obstacle_radius is not None or "obstacle_radius" in records)
    if "obstacle_pos" in records:
        # Every obstacle where it is at each env's last recorded step (moving ones move), with its radius (recorded
        # where it is drawn per episode, else `obstacle_radius`): the robot geoms' distances to each surface.
        positions = np.asarray(records["obstacle_pos"])
        count = positions.shape[-1] // 3
        radii = (np.asarray(records["obstacle_radius"]) if "obstacle_radius" in records
                 else np.full(positions.shape[:-1] + (count,), obstacle_radius or 0.0))
        last = np.minimum(length, positions.shape[0] - 1)

        def at(step):
            """(centres (env, obstacle, 3), radii (env, obstacle)) at each env's `step`."""
            return positions[step, np.arange(n)].reshape(n, count, 3), radii[step, np.arange(n)]

        def clearances(kin, where, radius):
            """Each robot geom's distance to each obstacle's surface, (env, obstacle, geom)."""
            return np.stack([np.asarray(jax.vmap(lambda c, x, m: robot.obstacle_distances(x, m, c, 0.0, geoms))(
                jnp.asarray(where[:, j]), kin.geom_xpos, kin.geom_xmat)) - radius[:, j, None]
                for j in range(count)], axis=1)

        centres, radius_end = at(last)
        surface = clearances(kin_end, centres, radius_end)
        obstacle_end = surface.min(axis=1)  # each geom's distance to the nearest obstacle's surface
        # The counterfactuals of `approach`: the arm held in its pose APPROACH_STEPS before the end while the
        # obstacles move on, and the obstacles held where they were then while the arm moves on.
        before = np.maximum(last - APPROACH_STEPS, 0)
        kin_before = robot.kinematics(jnp.asarray(qpos[before, np.arange(n)]))
        arm_held = clearances(kin_before, centres, radius_end).min(axis=(1, 2))
        obstacles_held = clearances(kin_end, *at(before)).min(axis=(1, 2))
        # What the paper's link distance read on the step the last action was chosen from: each link's frame origin
        # to the nearest obstacle's surface (the observation link_obstacle_dist with link_distance="origin").
        decided = np.maximum(last - 1, 0)
        kin_decided = robot.kinematics(jnp.asarray(qpos[decided, np.arange(n)]))
        where, radius = at(decided)
        origin_read = np.min([np.asarray(robot.link_obstacle_distances(
            kin_decided.xpos, kin_decided.geom_xpos, kin_decided.geom_xmat, jnp.asarray(where[:, j]),
            jnp.asarray(radius[:, j, None]), "origin")) for j in range(count)], axis=(0, 2))
        surface_before = clearances(kin_decided, where, radius).min(axis=(1, 2))  # the true clearance then
    if between:
        # an obstacle's sphere on the segment from the end effector to the target (any of them)
        target = jnp.asarray(np.asarray(records["target_pos"])[0])

        def blocked(kin, step):
            where, radius = at(step)
            return np.any([np.asarray(collision.point_segment_distance(jnp.asarray(where[:, j]), kin.ee_pos, target))
                           < radius[:, j] for j in range(count)], axis=0)

        blocked_start, blocked_end = blocked(kin_start, np.zeros(n, int)), blocked(kin_end, last)
    target_height = start_distance = in_target_before = None
    if "target_pos" in records:
        targets = np.asarray(records["target_pos"])
        target0 = targets[0]
        target_height = target0[:, 2]
        start_distance = np.linalg.norm(np.asarray(kin_start.ee_pos) - target0, axis=-1)
        if target_radius is not None:  # the end effector on the step before each episode's last one
            prev = np.clip(length - 1, 0, qpos.shape[0] - 1)
            ee_prev = np.asarray(robot.kinematics(jnp.asarray(qpos[prev, np.arange(n)])).ee_pos)
            in_target_before = np.linalg.norm(ee_prev - targets[prev, np.arange(n)], axis=-1) < target_radius
    pair_names = [" / ".join(_names(robot, pair)) for pair in robot.self_pairs]
    joint_names = [robot.mj_model.joint(j).name for j in range(robot.nq)]
    margin = np.minimum(end_q - robot.joint_low, robot.joint_high - end_q)
    at_limit = margin < LIMIT_MARGIN
    out = []
    for i in range(n):
        row = {"env": i, "step": int(length[i]), "start_clearance": float(self_start[i].min()),
               "at_limit": [joint_names[j] for j in np.flatnonzero(at_limit[i])],
               "joint_margin": float(margin[i].min()), "end_motion": float(end_motion[i])}
        if target_height is not None:
            row["target_height"] = float(target_height[i])
            row["start_distance"] = float(start_distance[i])
        if between:
            row["obstacle_between"] = {"start": bool(blocked_start[i])}
            row["final_obstacle_clearance"] = float(obstacle_end[i].min())
        if metrics["episode/self_collision"][i] > 0:
            row.update(outcome="self collision", what=pair_names[int(np.argmin(self_end[i]))])
        elif metrics.get("episode/obstacle_collision", np.zeros(n))[i] > 0:
            geom = geoms[int(np.argmin(obstacle_end[i]))]
            row.update(outcome="obstacle collision", what=_names(robot, [geom])[0],
                       approach=_approach(arm_held[i], obstacles_held[i], obstacle_end[i].min()),
                       approach_clearances={"arm_held": float(arm_held[i]),
                                            "obstacles_held": float(obstacles_held[i])},
                       origin_distance_before=float(origin_read[i]),
                       surface_distance_before=float(surface_before[i]))
            if "episode/steps_in_target" in metrics:  # steps in the target before the colliding one
                row["steps_in_target"] = int(metrics["episode/steps_in_target"][i])
            if in_target_before is not None:
                row["in_target_before"] = bool(in_target_before[i])
        elif metrics["episode/target_reached"][i] > 0:
            row.update(outcome="reached")
        else:
            row.update(outcome="missed", final_distance=float(metrics["episode/distance"][i]))
            if between:
                row["obstacle_between"]["end"] = bool(blocked_end[i])
        out.append(row)
    return out


def _approach(arm_held: float, obstacles_held: float, contact: float) -> str:
    """Whose motion a collision needed: the obstacles' alone ("obstacle": it comes as close with the arm held),
    the arm's alone ("arm"), "either" alone, or only "both" together. `contact`: the clearance at the collision's
    recorded pose (a contact between recorded poses can leave it above 0), the closeness that counts as the same."""
    reach = max(contact, 0.0)
    obstacle, arm = arm_held <= reach, obstacles_held <= reach
    return "either" if obstacle and arm else "obstacle" if obstacle else "arm" if arm else "both"


def _median_by_outcome(by: dict, field: str) -> dict:
    return {k: float(np.median([r[field] for r in v])) for k, v in sorted(by.items()) if v}


def _bins(values, edges) -> tuple[np.ndarray, list[str]]:
    """Each value's bin index into the labels of `edges` (m; bin k holds edges[k-1] <= v < edges[k], the
    outer bins open) and those labels in cm."""
    cm = lambda x: f"{x * 100:g}"
    labels = ([f"< {cm(edges[0])} cm"] + [f"{cm(a)}-{cm(b)} cm" for a, b in zip(edges, edges[1:])]
              + [f"> {cm(edges[-1])} cm"])
    return np.searchsorted(np.asarray(edges), np.asarray(values), side="right"), labels


def summarize(rows: list[dict], near_limit: float = NEAR_LIMIT) -> dict:
    """Counts and rates of outcomes, collisions by pair/geom, steps and clearances, miss distances;
    `near_limit` (rad) is the joint margin counted as near a limit."""
    n = len(rows)
    by = collections.defaultdict(list)
    for r in rows:
        by[r["outcome"]].append(r)
    summary = {"episodes": n, "outcomes": {k: len(v) / n for k, v in sorted(by.items())}}
    collided = by["self collision"] + by["obstacle collision"]
    if collided:
        steps = np.array([r["step"] for r in collided])
        summary["collisions"] = {
            "by_part": dict(collections.Counter(f"{r['outcome']}: {r['what']}" for r in collided).most_common()),
            "step_quartiles": [float(q) for q in np.percentile(steps, [25, 50, 75])],
            "within_first_5_steps": float(np.mean(steps <= 5)),
            "start_clearance_median": float(np.median([r["start_clearance"] for r in collided])),
        }
        obstacle = by["obstacle collision"]
        fields = obstacle[0] if obstacle else {}  # what the rows record (reports made before a field lack it)
        approaches = lambda rows: dict(collections.Counter(r["approach"] for r in rows).most_common())
        if "approach" in fields:
            summary["collisions"]["obstacle_approach"] = approaches(obstacle)
            summary["collisions"]["approach_steps"] = APPROACH_STEPS
        if "steps_in_target" in fields:
            after = [r for r in obstacle if r["steps_in_target"] > 0]
            summary["collisions"]["obstacle_after_target"] = len(after)
            if "approach" in fields:
                summary["collisions"]["obstacle_approach_after_target"] = approaches(after)
        if "in_target_before" in fields:
            summary["collisions"]["obstacle_in_target_before"] = sum(r["in_target_before"] for r in obstacle)
        for name in ("origin_distance_before", "surface_distance_before"):
            if name in fields:
                read = np.array([r[name] for r in obstacle])
                summary["collisions"][name] = {"median": float(np.median(read)),
                                               "share_over_10cm": float(np.mean(read > 0.1))}
    summary["start_clearance_median_all"] = float(np.median([r["start_clearance"] for r in rows]))
    if by["missed"]:
        index, labels = _bins([r["final_distance"] for r in by["missed"]], (0.0,) + MISS_BINS)
        summary["missed_final_distance"] = {lab: int(np.sum(index == k)) for k, lab in enumerate(labels) if k}
    summary["ending_at_a_joint_limit"] = {k: float(np.mean([bool(r["at_limit"]) for r in v]))
                                          for k, v in sorted(by.items()) if v}
    motion, margin = _median_by_outcome(by, "end_motion"), _median_by_outcome(by, "joint_margin")
    summary["near_limit_margin"] = near_limit
    summary["end"] = {k: {"end_motion_median": motion[k], "joint_margin_median": margin[k],
                          "near_limit": float(np.mean([r["joint_margin"] < near_limit for r in v]))}
                      for k, v in sorted(by.items()) if v}
    if by["missed"]:
        summary["missed_by_joint_at_limit"] = dict(collections.Counter(
            j for r in by["missed"] for j in r["at_limit"]).most_common())
    if rows and "obstacle_between" in rows[0]:
        summary["obstacle_between_at_start"] = {k: float(np.mean([r["obstacle_between"]["start"] for r in v]))
                                                for k, v in sorted(by.items()) if v}
        if by["missed"]:
            summary["missed_obstacle_between_at_end"] = float(np.mean([r["obstacle_between"]["end"] for r in by["missed"]]))
        clearance = _median_by_outcome(by, "final_obstacle_clearance")
        summary["final_obstacle_clearance"] = {
            k: {"median": clearance[k], "near": float(np.mean([r["final_obstacle_clearance"] < PROXIMITY for r in v]))}
            for k, v in sorted(by.items()) if v}
    if rows and "target_height" in rows[0]:
        summary["by_target_height"] = outcomes_by_height(rows)
        summary["start_distance_median"] = _median_by_outcome(by, "start_distance")
    return summary


def outcomes_by_height(rows: list[dict], edges=HEIGHT_BINS) -> dict:
    """Per target-height bin (labels from `edges`, m): its episodes and the share of each outcome."""
    index, labels = _bins([r["target_height"] for r in rows], edges)
    outcomes = sorted({r["outcome"] for r in rows})
    out = {}
    for b, label in enumerate(labels):
        members = [r for r, k in zip(rows, index) if k == b]
        if members:
            out[label] = {"episodes": len(members),
                          **{o: sum(r["outcome"] == o for r in members) / len(members) for o in outcomes}}
    return out


def markdown(summary: dict, title: str) -> str:
    pct = lambda x: f"{100 * x:.1f} %"
    lines = [f"### {title}", "", f"{summary['episodes']} episodes", "", "| outcome | share |", "|---|---:|"]
    lines += [f"| {k} | {pct(v)} |" for k, v in summary["outcomes"].items()]
    if "collisions" in summary:
        c = summary["collisions"]
        lines += ["", "| collision | episodes |", "|---|---:|"] + [f"| {k} | {v} |" for k, v in c["by_part"].items()]
        q = c["step_quartiles"]
        lines += ["", f"collision step quartiles {q[0]:g} / {q[1]:g} / {q[2]:g}; within the first 5 steps "
                      f"{pct(c['within_first_5_steps'])}; start pose's self-collision clearance (median) of collided "
                      f"episodes {c['start_clearance_median'] * 100:.1f} cm against "
                      f"{summary['start_clearance_median_all'] * 100:.1f} cm over all episodes"]
        if "obstacle_approach" in c:
            lines += ["", f"obstacle collisions by whose motion over the last {APPROACH_STEPS} steps brought the "
                          "contact: " + ", ".join(f"{k} {v}" for k, v in c["obstacle_approach"].items())]
        if "obstacle_after_target" in c:
            by_approach = ", ".join(f"{k} {v}" for k, v in c.get("obstacle_approach_after_target", {}).items())
            lines += ["", "obstacle collisions after the end effector had reached the target: "
                          f"{c['obstacle_after_target']}" + (f" ({by_approach})" if by_approach else "")]
        if "obstacle_in_target_before" in c:
            lines += ["", "obstacle collisions with the end effector in the target on the step before: "
                          f"{c['obstacle_in_target_before']}"]
        if "origin_distance_before" in c:
            o = c["origin_distance_before"]
            lines += ["", "obstacle collisions: the nearest link origin's distance to an obstacle surface on the step "
                          "before (the paper's d_i, observed with link_distance=\"origin\"): "
                          f"median {o['median'] * 100:.1f} cm, over 10 cm in {pct(o['share_over_10cm'])}"]
        if "surface_distance_before" in c:
            o = c["surface_distance_before"]
            lines += ["", "obstacle collisions: the robot's true clearance from the obstacles on the step before "
                          "(observed with link_distance=\"surface\"): "
                          f"median {o['median'] * 100:.1f} cm, over 10 cm in {pct(o['share_over_10cm'])}"]
    if "missed_final_distance" in summary:
        lines += ["", "missed episodes by final distance: " + ", ".join(
            f"{k}: {v}" for k, v in summary["missed_final_distance"].items())]
    lines += ["", f"episodes ending with a joint within {LIMIT_MARGIN} rad of its range limit: " + ", ".join(
        f"{k} {pct(v)}" for k, v in summary["ending_at_a_joint_limit"].items())]
    if "end" in summary:
        lines += ["", f"at the end (medians): end effector's motion over the last {END_STEPS} steps, smallest joint "
                  f"margin, share with a joint within {summary['near_limit_margin']} rad of a limit: " + "; ".join(
                      f"{k} {v['end_motion_median'] * 100:.1f} cm, {v['joint_margin_median']:.2f} rad, {pct(v['near_limit'])}"
                      for k, v in summary["end"].items())]
    if summary.get("missed_by_joint_at_limit"):
        lines += ["", "joints at a limit at the end of missed episodes: " + ", ".join(
            f"{k}: {v}" for k, v in summary["missed_by_joint_at_limit"].items())]
    if "obstacle_between_at_start" in summary:
        lines += ["", "episodes starting with the obstacle on the straight line from the end effector to the target: "
                  + ", ".join(f"{k} {pct(v)}" for k, v in summary["obstacle_between_at_start"].items())]
        if "missed_obstacle_between_at_end" in summary:
            lines[-1] += f"; missed episodes ending with it there: {pct(summary['missed_obstacle_between_at_end'])}"
        lines += ["", f"robot's clearance from the obstacle at the end (median; share within {PROXIMITY} m): " + ", ".join(
            f"{k} {v['median'] * 100:.1f} cm, {pct(v['near'])}" for k, v in summary["final_obstacle_clearance"].items())]
    if "start_distance_median" in summary:
        lines += ["", "end effector's distance from the target at the start (median): " + ", ".join(
            f"{k} {v * 100:.1f} cm" for k, v in summary["start_distance_median"].items())]
    if "by_target_height" in summary:
        bins = summary["by_target_height"]
        outcomes = [k for k in next(iter(bins.values())) if k != "episodes"]
        lines += ["", "| target height | episodes | " + " | ".join(outcomes) + " |",
                  "|---|---:|" + "---:|" * len(outcomes)]
        lines += [f"| {label} | {b['episodes']} | " + " | ".join(pct(b[o]) for o in outcomes) + " |"
                  for label, b in bins.items()]
    return "\n".join(lines) + "\n"


OUTCOME_COLORS = {"reached": "tab:green", "self collision": "tab:red", "obstacle collision": "tab:orange",
                  "missed": "tab:gray"}
"""The outcomes in the figure's order, with their colours."""


def figure(summary: dict, title: str, out: str | None = None):
    """The report as a picture: the outcomes' shares, the colliding parts (episodes each) and the outcomes by target
    height above the mounting plane (share of that height's episodes)."""
    from tools import plots

    plt = plots.pyplot()
    fig, (a, b, c) = plt.subplots(1, 3, figsize=(13, 3.6), gridspec_kw={"width_ratios": [1, 1.6, 1.4]})
    names = [o for o in OUTCOME_COLORS if o in summary["outcomes"]]
    a.bar(range(len(names)), [100 * summary["outcomes"][o] for o in names], color=[OUTCOME_COLORS[o] for o in names])
    a.set_xticks(range(len(names)), [o.replace(" ", "\n") for o in names], fontsize=8)
    a.set_ylabel(f"% of {summary['episodes']} episodes")
    parts = sorted(summary["collisions"].get("by_part", {}).items(), key=lambda kv: -kv[1])
    b.barh(range(len(parts)), [n for _, n in parts],
           color=[OUTCOME_COLORS[p.split(":")[0]] for p, _ in parts])
    b.set_yticks(range(len(parts)), [p.split(": ", 1)[1] for p, _ in parts], fontsize=8)
    b.invert_yaxis()
    b.set_xlabel("collided episodes, by the closest pair")
    heights = summary.get("by_target_height", {})
    bottom = np.zeros(len(heights))
    for o in names:
        share = np.array([100 * h.get(o, 0.0) for h in heights.values()])
        c.bar(range(len(heights)), share, bottom=bottom, color=OUTCOME_COLORS[o], label=o)
        bottom += share
    c.set_xticks(range(len(heights)), [f"{k}\n({h['episodes']})" for k, h in heights.items()], fontsize=7)
    c.set_xlabel("target height above the mounting plane (episodes)")
    c.legend(fontsize=7, loc="lower right")
    fig.suptitle(title, fontsize=9)
    fig.tight_layout()
    return plots.save(fig, out)


def _is_option(token: str) -> bool:
    """A command-line option, not a value (a negative number is a value)."""
    try:
        float(token)
        return False
    except ValueError:
        return token.startswith("-")


def refuse_unknown_options(argv: list[str]) -> None:
    """ValueError naming the first token left over by the tool's own options that is neither an `--env.<field>`
    option nor one of its values."""
    unknown = [a for i, a in enumerate(argv)
               if (_is_option(a) and not a.startswith("--env.")) or (i == 0 and not _is_option(a))]
    if unknown:
        raise ValueError(f"option {unknown[0]!r} is unknown: allowed are this tool's options (--help) and "
                         "--env.<field> VALUE (eval.py --checkpoint PATH --help lists the fields).")


def env_options(config, argv: list[str]):
    """`config` with eval.py's `--env.<field> VALUE` options in `argv` replacing fields; any other option: ValueError
    naming it; a bad value: tyro's message and exit status 2, as in eval.py."""
    refuse_unknown_options(argv)
    if not argv:
        return config
    args = ["--" + a[len("--env."):] if a.startswith("--env.") else a for a in argv]
    return tyro.cli(type(config), default=config, args=args, prog="python -m tools.failure_report --env.<field>")


def main(argv: list[str] | None = None) -> dict:
    import envs
    from agents import evaluation, provenance

    p = argparse.ArgumentParser(prog="python -m tools.failure_report", description=__doc__.splitlines()[0],
                                epilog="--env.<field> VALUE replaces a field of the checkpoint's env config, as in "
                                       "eval.py (eval.py --checkpoint PATH --help lists the fields).")
    p.add_argument("--checkpoint", help="train.py logdir, checkpoint step directory or policy export")
    p.add_argument("--from-json", metavar="PATH", help="draw --plot from a report written earlier with --json")
    p.add_argument("--plot", metavar="PNG", help="the report as a picture (needs matplotlib: the viz extra)")
    p.add_argument("--env", help="registered env name (default: the checkpoint's)")
    p.add_argument("--num-envs", type=int, default=256)
    p.add_argument("--unit", type=int, default=0, help="index of the trained seed in the checkpoint (default 0)")
    p.add_argument("--seed", type=int, default=7, help="evaluation seed (default 7)")
    p.add_argument("--json", metavar="PATH", help="write the summary and every episode's row")
    p.add_argument("--allow-env-mismatch", action="store_true",
                   help="as eval.py's: warn instead of refusing where the --env.* options change what the policy saw")
    args, env_argv = p.parse_known_args(argv)
    if bool(args.checkpoint) == bool(args.from_json):
        raise ValueError("give exactly one of --checkpoint PATH (run the episodes) and --from-json PATH (a report "
                         "written earlier).")
    refuse_unknown_options(env_argv)
    if args.from_json:
        if env_argv:
            raise ValueError(f"{env_argv[0]!r} is invalid with --from-json: allowed only with --checkpoint.")
        if not args.plot:
            raise ValueError("--from-json needs --plot PNG: allowed is drawing a report written earlier.")
        with open(args.from_json) as f:
            report = json.load(f)
        figure(report["summary"], report.get("note") or args.from_json, args.plot)
        return report["summary"]
    policy = evaluation.checkpoint_policy(args.checkpoint)
    if not 0 <= args.unit < len(policy.units):
        raise ValueError(f"--unit {args.unit} is invalid: allowed is 0 ... {len(policy.units) - 1} "
                         f"(the checkpoint's seeds {policy.units}).")
    if args.num_envs < 1:
        raise ValueError(f"--num-envs {args.num_envs} is invalid: allowed is an integer >= 1.")
    env_name = args.env or policy.train_env_name
    base = envs.make_config(env_name, policy.train_env_config)
    config = env_options(base, env_argv)
    changed = ", ".join(f"{f.name}={getattr(config, f.name)}" for f in dataclasses.fields(config)
                        if getattr(config, f.name) != getattr(base, f.name))
    # What made it, read before the run: rewriting a tracked report would otherwise mark the code modified.
    made = provenance.stamp(provenance.command(None if argv is None else [__file__] + list(argv)))
    records = evaluation.rollout(policy, env_name, config, num_envs=args.num_envs, eval_seed=args.seed, unit=args.unit,
                                 allow_env_mismatch=args.allow_env_mismatch)  # checked before any episode runs
    env = envs.from_config(env_name, config)
    rows = classify(env.robot, records, getattr(config, "obstacle_radius", None), getattr(env, "checked_geoms", None),
                    getattr(config, "target_radius", None))
    summary = summarize(rows, getattr(config, "joint_limit_margin", NEAR_LIMIT))
    title = f"{args.checkpoint} (seed {policy.units[args.unit]}) on {env_name}{f' ({changed})' if changed else ''}, " \
            f"eval seed {args.seed}"
    print(markdown(summary, title))
    if args.plot:
        figure(summary, title, args.plot)
    if args.json:
        with open(args.json, "w") as f:
            json.dump({**made, "summary": summary, "episodes": rows}, f, indent=1)
    return summary


if __name__ == "__main__":
    run_cli(main)
