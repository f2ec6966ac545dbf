"""Statistics of evaluation results over units (trained seeds) and episodes: the summary every table reads (mean,
sample and population spreads, the mean's 95 % confidence interval by rliable), two extra readings of the final
distance, the pooled summary of several checkpoints, the "mean ± std [low, high]" cell, and strict-JSON values."""

from __future__ import annotations

import math
import warnings

import numpy as np

from agents import intervals


def collided_distances(per_env: dict) -> dict:
    """Two readings of the final distance for comparing with other evaluators (not in our tables'
    main columns): `distance_collided_as_0` counts an episode that ended in a collision as 0, which
    is what summing per-step metrics over an episode's *active* steps gives when the distance is
    only recorded over the last steps (Brax's evaluator); `distance_not_collided` is the mean over
    collision-free episodes only (NaN if there are none)."""
    if "distance" not in per_env or "self_collision" not in per_env:
        return {}
    collided = per_env["self_collision"] > 0
    if "obstacle_collision" in per_env:
        collided |= per_env["obstacle_collision"] > 0
    return {"distance_collided_as_0": np.where(collided, 0.0, per_env["distance"]),
            "distance_not_collided": np.where(collided, np.nan, per_env["distance"])}


def reached_precision(per_env: dict) -> dict:
    """Precision of the episodes that reached the target (NaN for the others): `distance_reached`, the final
    distance, and `steps_in_target_reached`. The main columns average over every episode, where the few that
    never reach (tens of centimetres away) dominate a mean distance of millimetres."""
    if "target_reached" not in per_env:
        return {}
    reached = per_env["target_reached"] > 0
    return {f"{name}_reached": np.where(reached, per_env[name], np.nan)
            for name in ("distance", "steps_in_target") if name in per_env}


def summarize(per_env: dict) -> dict:
    """{metric: {mean, std_units, ci95_units, std_episodes, units, episodes}} from (units, envs) arrays: the
    mean over units of each unit's mean, its standard deviation over units (ddof 0, as over seeds), the mean's
    95 % bootstrap confidence interval over units (rliable, `agents.intervals`; None for one unit), and the
    standard deviation over all episodes pooled."""
    out = {}
    for name, values in per_env.items():
        values = np.asarray(values, np.float64)
        with np.errstate(invalid="ignore"), warnings.catch_warnings():
            warnings.simplefilter("ignore", RuntimeWarning)  # all-NaN units (e.g. no collision-free episode)
            unit_means = np.nanmean(values, axis=1)
            out[name] = {"mean": float(np.nanmean(unit_means)), "std_units": float(np.nanstd(unit_means)),
                         "ci95_units": intervals.mean_ci(unit_means), "std_episodes": float(np.nanstd(values)),
                         "units": int(values.shape[0]), "episodes": int(np.sum(~np.isnan(values)))}
    return out


def pooled(results: list) -> dict | None:
    """The summary over the units of several results (e.g. one checkpoint per seed), or None if
    their env configs differ."""
    if len({(r.env_name, r.env_config) for r in results}) != 1:
        return None
    names = set.intersection(*(set(r.per_env) for r in results))
    if len({r.num_envs for r in results}) != 1:
        return None
    return summarize({n: np.concatenate([r.per_env[n] for r in results]) for n in sorted(names)})


def sample_std(stats: dict) -> float:
    """The sample std over units (ddof 1) of a summary entry, whose `std_units` is the population std."""
    n = stats["units"]
    return stats["std_units"] * math.sqrt(n / (n - 1))


def fmt(stats: dict | None, digits: int, spread: str = "std_units", ci: bool = False) -> str:
    """"mean ± std" (over units the sample std, ddof 1, from the summary's population `std_units`; omitted with a
    single unit; or `spread="std_episodes"`), or "-" if missing; with `ci` the mean's 95 % confidence interval over
    units follows in brackets where there is one."""
    if not stats or not math.isfinite(stats["mean"]):
        return "-"
    text = f"{stats['mean']:.{digits}f}"
    if spread == "std_episodes":
        text += f" ± {stats[spread]:.{digits}f}"
    elif stats["units"] > 1:
        text += f" ± {sample_std(stats):.{digits}f}"
    interval = stats.get("ci95_units") if ci else None
    if interval:
        text += f" [{interval[0]:.{digits}f}, {interval[1]:.{digits}f}]"
    return text


def jsonable(obj):
    """`obj` with NaN / inf floats as None (strict JSON) and tuples as lists."""
    if isinstance(obj, dict):
        return {k: jsonable(v) for k, v in obj.items()}
    if isinstance(obj, (list, tuple)):
        return [jsonable(v) for v in obj]
    if isinstance(obj, float) and not math.isfinite(obj):
        return None
    return obj


def overruled_share(units: list) -> float:
    """A shielded policy's overruled steps over all executed steps of `units`' episodes (each unit's means over the
    same number of episodes, so the ratio of their sums is the pooled share)."""
    return (sum(u["metrics"]["overruled_steps"] for u in units) / sum(u["metrics"]["episode_length"] for u in units))


def seed_line(k: int, n: int, eval_seed: int, units: list, seconds: float) -> str:
    """"eval seed k of n (seed): x% reached, y% self collision ..., elapsed" over one seed's units."""
    parts = []
    for name, what in (("target_reached", "reached"), ("self_collision", "self collision"),
                       ("obstacle_collision", "obstacle collision")):
        if name in units[0]["metrics"]:
            parts.append(f"{100 * np.mean([u['metrics'][name] for u in units]):.1f} % {what}")
    if "overruled_steps" in units[0]["metrics"]:  # a shielded policy: the share of executed steps it overruled
        parts.append(f"{100 * overruled_share(units):.1f} % of steps overruled")
    each = ", ".join(f"{100 * u['metrics'].get('target_reached', np.nan):.1f}" for u in units)  # the log keeps them
    over = f" (mean over {len(units)} trained seeds; reached % each: {each})" if len(units) > 1 else ""
    return f"eval seed {k + 1} of {n} ({eval_seed}): {', '.join(parts)}{over}; {seconds:.0f} s elapsed"
