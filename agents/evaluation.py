"""Evaluation of trained policies and baselines on any env configuration (the library behind eval.py
and tools/paper_tables.py).

    import envs
    from agents import evaluation
    policy = evaluation.checkpoint_policy("runs/ur5e-reach-ppo/20250101-120000")
    config = envs.make_config("ur5e-reach", policy.train_env_config, workspace="front")
    result = evaluation.run(policy, "ur5e-reach", config, num_envs=4096, eval_seeds=[1_000_000])
    print(evaluation.markdown([result]))

A policy is a checkpoint's policy export (`agents.export`, one unit per trained seed), a baseline
(`agents.baselines`), the MPPI planner (`agents.planner`) or a checkpoint's policy shielded by the planner's model
(`agents.shield`). Every unit (trained seed x evaluation seed) runs `num_envs` environments for
one episode each with the deterministic policy (`agents.loop.make_evaluate`); the same evaluation
seed gives every policy the same episodes. Reported per unit: the mean over episodes of each paper
metric (`PAPER_METRICS`); summarised as mean and standard deviation over units, plus the standard
deviation over all episodes (the paper's baseline table gives that one for the distance).
"""

from __future__ import annotations

import dataclasses
import functools
import sys
import time
import warnings
from typing import Any, Callable

import jax
import numpy as np

import envs
from agents import baselines, driver, export, intervals, planner as planners, program_store, registry, shield
from agents.compatibility import LAYOUT_FIELDS, check, check_compatible, unseen_constants  # noqa: F401 (evaluation.check, ...)
from envs import physics
from agents.loop import make_evaluate, make_evaluate_stacked
from agents.networks import COMPUTE_DTYPES
from agents.eval_stats import (collided_distances, fmt, jsonable, pooled, reached_precision,  # noqa: F401 (evaluation.fmt, ...)
                                seed_line, summarize)

PAPER_METRICS = {"target_reached": "episode/target_reached", "self_collision": "episode/self_collision",
                 "obstacle_collision": "episode/obstacle_collision", "distance": "episode/distance_last10",
                 "steps_in_target": "episode/steps_in_target", "times_left_target": "episode/times_left_target"}
"""The paper's metrics (section "Training and evaluation", tables) and the `make_evaluate` key each
is read from; all are an episode's values at its last step. `distance` is the mean end-effector to
target distance over the episode's last 10 steps (the env's `distance_last10`)."""
EXTRA_METRICS = {"episode_length": "episode/length", "return": "episode/return", "physics_nan": "episode/physics_nan",
                 "reset_fallback": "episode/reset_fallback", "mean_joint_vel": "episode/mean_joint_vel",
                 "mean_joint_acc": "episode/mean_joint_acc", "overruled_steps": "episode/overruled_steps"}
"""Also reported (JSON / CSV), not part of the paper's tables; `mean_joint_vel` and `mean_joint_acc` (rad/s,
rad/s^2) are an episode's mean joint speed and acceleration norms (`envs.arm.METRICS`); `overruled_steps`, a
shielded policy's steps not its own (`agents.shield`)."""
DEFAULT_EVAL_SEED = 1_000_000
"""The training driver's `eval_seed`: eval.py on a run's own env config reproduces its eval.json."""


# ------------------------------------------------------------------------------------------------
# Policies


@dataclasses.dataclass
class Policy:
    """What to evaluate: a checkpoint's policy (one unit per trained seed), a baseline or the planner."""

    kind: str
    """"checkpoint", "baseline", "planner" or "shielded" (a checkpoint's policy shielded by the planner)."""
    name: str
    """The baseline's or planner's name, or the checkpoint's path as given."""
    units: list
    """Labels of the policy's units: trained seeds (checkpoint, shielded) or [None] (baseline, planner)."""
    export: export.PolicyExport | None = None
    planner: planners.PlannerConfig | None = None
    """The planner's options (kind "planner"; kind "shielded": its fallback's, `agents.shield`)."""
    compute_dtype: str | None = None
    """The number format of the network's hidden layers in this evaluation (learners with a `compute_dtype`
    field, `with_compute_dtype`); None: as trained."""

    @property
    def algo_config(self):
        """The learner config the evaluation acts with: the trained one, with `compute_dtype` applied."""
        if self.export is None:
            return None
        algo = self.export.config.algo
        if self.compute_dtype and hasattr(algo, "compute_dtype"):
            return dataclasses.replace(algo, compute_dtype=self.compute_dtype)
        return algo

    @property
    def train_env_name(self) -> str | None:
        return self.export.env_name if self.export else None

    @property
    def train_env_config(self):
        return self.export.config.env if self.export else None

    @property
    def model_steps_per_step(self) -> int | None:
        """Env steps simulated in the model per executed one: the planner's or the shield's; None for the others."""
        if self.planner is None:
            return None
        return self.planner.model_steps_per_step if self.export is None else shield.model_steps_per_step(self.planner)

    def describe(self) -> dict:
        if self.planner is not None and self.export is None:
            return {"kind": self.kind, "name": self.name, "planner": dataclasses.asdict(self.planner),
                    "model_steps_per_step": self.model_steps_per_step}
        if self.export is None:
            return {"kind": self.kind, "name": self.name}
        e = self.export
        out = {"kind": self.kind, "name": self.name, "export": e.path, "env_steps": e.env_steps,
               "algo": e.config.algo_name, "train_env_name": e.env_name, "seeds": e.seeds,
               "train_config": e.meta["config"]}
        if self.compute_dtype:
            out["compute_dtype"] = self.compute_dtype
        if self.planner is not None:
            out.update(planner=dataclasses.asdict(self.planner), model_steps_per_step=self.model_steps_per_step)
        return out


def with_compute_dtype(policy: Policy, dtype: str | None) -> Policy:
    """`policy` evaluated with its hidden layers in `dtype` (float32 or bfloat16; None: as trained), to
    measure what the number format does to a trained policy; ValueError for a baseline or a learner
    without that setting."""
    if dtype is None:
        return policy
    if policy.export is None or not hasattr(policy.export.config.algo, "compute_dtype"):
        what = f"the baseline {policy.name!r}" if policy.export is None else \
            f"{policy.name!r} ({policy.export.config.algo_name}, which has no compute_dtype setting)"
        raise ValueError(f"compute_dtype={dtype!r} is invalid for {what}: allowed only for checkpoints of learners "
                         "with a compute_dtype setting.")
    if dtype not in COMPUTE_DTYPES:
        raise ValueError(f"compute_dtype={dtype!r} is invalid: allowed are {', '.join(map(repr, COMPUTE_DTYPES))}.")
    return dataclasses.replace(policy, compute_dtype=dtype)


def baseline_policy(name: str) -> Policy:
    baselines.index(name)  # unknown name -> ValueError
    return Policy("baseline", name, [None])


def planner_policy(config: planners.PlannerConfig = planners.PlannerConfig()) -> Policy:
    """The MPPI planner (`agents.planner`) with `config`: it plans with the env itself, on any env."""
    return Policy("planner", planners.NAME, [None], planner=config)


def shielded_policy(policy: Policy, config: planners.PlannerConfig = planners.PlannerConfig()) -> Policy:
    """`policy`, a checkpoint's, shielded by the planner with `config` (`agents.shield`); ValueError for a baseline or
    the planner, which have no policy of their own to shield."""
    if policy.export is None:
        raise ValueError(f"shielding the {policy.kind} {policy.name!r} is invalid: allowed only for checkpoints.")
    return dataclasses.replace(policy, kind="shielded", planner=config)


def act_params(policy: Policy):
    """What the evaluation program takes as its first argument: the trained parameters, the baseline's index,
    or nothing the planner reads."""
    if policy.export is not None:
        return policy.export.state
    return baselines.index(policy.name) if policy.planner is None else np.int32(0)


def checkpoint_policy(path: str) -> Policy:
    """The policy export that `path` names (a train.py logdir: its newest checkpoint; a checkpoint
    step directory; an export directory). A checkpoint from before exports existed gets one written
    first (its full training state is restored once)."""
    try:
        loaded = export.load(path)
    except export.MissingExport as missing:
        print(f"note: {missing.step_dir} has no policy export; writing one from the full checkpoint.", file=sys.stderr)
        loaded = _rebuild_export(missing.step_dir)
    except export.CorruptExport as corrupt:
        if corrupt.step_dir is None:  # an export without its checkpoint (e.g. one copied elsewhere)
            raise
        print(f"note: {corrupt}; rebuilding it from the full checkpoint.", file=sys.stderr)
        loaded = _rebuild_export(corrupt.step_dir, because=str(corrupt))
    return Policy("checkpoint", path, list(loaded.seeds), loaded)


def _rebuild_export(step_dir: str, because: str = "") -> export.PolicyExport:
    """The policy export written anew from the full checkpoint in `step_dir`."""
    try:
        driver.export_checkpoint(step_dir)
    except Exception as error:  # orbax / tensorstore raise many types on a broken checkpoint
        raise ValueError((f"{because}; and " if because else "") + f"checkpoint {step_dir!r} is corrupt or unreadable: "
                         f"{type(error).__name__}: {str(error).splitlines()[0] if str(error) else ''}") from None
    return export.load(step_dir)


# ------------------------------------------------------------------------------------------------
# Running


@dataclasses.dataclass
class Program:
    """A batched env and its jitted `evaluate(params, key) -> (per-env metrics, records)`."""

    env: Any
    evaluate: Callable
    compiled: set = dataclasses.field(default_factory=set)
    """Trained-seed counts (0 for baselines) it has run with, i.e. compiled for: progress says when a call compiles."""


def evaluate_fn(env, algo_config, obs_size: int, act_size: int, num_envs: int, length: int, last_steps: int,
                stochastic: bool = False, planner: planners.PlannerConfig | None = None) -> Callable:
    """The unjitted `evaluate(params, key) -> (per-env metrics, records)` on the batched `env` (`_evaluator`, `agents.sweep`
    jit it): the network's of `algo_config` shielded by `planner` where both are given (`agents.shield`), else the
    planner's, else a baseline's (no `algo_config`), else the network's."""
    if planner is not None and algo_config is not None:
        learner = registry.make_learner(algo_config, obs_size, act_size)
        unit_act, unit_memory = shield.make_unit_act(env, learner, planner)
        return make_evaluate_stacked(env, learner, num_envs, length, last_steps, per_env=True, record=_record,
                                     unit_act=unit_act, unit_memory=unit_memory, memory_metrics=shield.memory_metrics)
    if planner is not None:
        act, memory = planners.make_act(env, planner)
        return make_evaluate(env, None, num_envs, length, last_steps, act=act, per_env=True, record=_record, memory=memory)
    if algo_config is None:
        return make_evaluate(env, None, num_envs, length, last_steps, act=baselines.make_act(env), per_env=True,
                             record=_record)
    learner = registry.make_learner(algo_config, obs_size, act_size)
    return make_evaluate_stacked(env, learner, num_envs, length, last_steps, stochastic, per_env=True, record=_record)


@functools.lru_cache(maxsize=16)
def _evaluator(env_name: str, env_config, algo_config, obs_size: int, act_size: int, num_envs: int, last_steps: int,
               stochastic: bool = False, planner: planners.PlannerConfig | None = None) -> Program:
    """The evaluation program, cached per setting so that several checkpoints / seeds / baselines (and a video of as
    many envs) share one compilation. The env is not auto-reset (`envs.wrap(..., autoreset=False)`): only each env's
    first episode counts, and its poses are recorded for rendering. `stochastic`: actions drawn from the policy's
    distribution (a fresh key per step) instead of its mode; `planner`: the MPPI planner with these options acts."""
    env = envs.wrap(envs.registry.build(env_name, env_config), autoreset=False)  # checked by `_program`
    fn = jax.jit(evaluate_fn(env, algo_config, obs_size, act_size, num_envs, env_config.episode_length, last_steps,
                             stochastic, planner))
    described = ("evaluation", env_name, env_config, algo_config, obs_size, act_size, num_envs, last_steps, stochastic,
                 planner)
    return Program(env, program_store.Stored(fn, described))


def _program(policy: Policy, env_name: str, env_config, num_envs: int, last_steps: int, stochastic: bool,
             allow_env_mismatch: bool = False) -> Program:
    """The cached evaluation program (`_evaluator`) for `policy` on this env, after checking the env config, that the
    env fits the policy and that a stochastic evaluation has a distribution to sample."""
    envs.registry.check_config(env_name, env_config)
    check_stochastic(policy, stochastic)
    e = policy.export
    program = _evaluator(env_name, env_config, policy.algo_config, e.observation_size if e else 0,
                         e.action_size if e else 0, int(num_envs), int(last_steps), bool(stochastic), policy.planner)
    check_compatible(policy, env_name, program.env, allow_env_mismatch)
    return program


def _record(state):
    """What a video needs of each step: joint positions, target and obstacles (arms only)."""
    if not hasattr(state.pipeline_state, "qpos"):
        return {}
    out = {"qpos": state.pipeline_state.qpos, "target_pos": state.info["target_pos"]}
    for key in ("obstacle_pos", "obstacle_radius"):  # the radius where it is drawn per episode
        if key in state.info:
            out[key] = state.info[key]
    return out


@dataclasses.dataclass
class Result:
    """One policy on one env configuration."""

    policy: Policy
    env_name: str
    env_config: Any
    num_envs: int
    eval_seeds: list
    last_steps: int
    units: list
    """[{"policy_seed", "eval_seed", "metrics": {name: mean over episodes}}]."""
    per_env: dict
    """{name: array (units, num_envs)}: every episode's value (for stds over episodes)."""
    seconds: float
    """Wall time of the evaluation, compilation included."""
    seed_seconds: list = dataclasses.field(default_factory=list)
    """Wall time of each evaluation seed (the first includes compiling unless the program was compiled before)."""
    stochastic: bool = False
    """Actions drawn from the policy's distribution instead of its mode (deterministic, the default)."""

    def summary(self) -> dict:
        """Means, stds and intervals of the metrics; computed once (the intervals resample)."""
        return self._summary

    @functools.cached_property
    def _summary(self) -> dict:
        return summarize(self.per_env)

    def to_json(self) -> dict:
        return jsonable({
            "policy": self.policy.describe(),
            "env_name": self.env_name,
            "env_config": dataclasses.asdict(self.env_config),
            "physics": _physics_backend(self.env_config),
            "num_envs": self.num_envs,
            "eval_seeds": list(self.eval_seeds),
            "last_steps": self.last_steps,
            "episodes": int(self.num_envs * len(self.units)),
            "actions": "stochastic" if self.stochastic else "deterministic",
            "seconds": round(self.seconds, 2),
            "seed_seconds": [round(t, 3) for t in self.seed_seconds],
            "summary": self.summary(),
            "units": self.units,
        })


def _metric_names(per_step: dict, last_steps: int) -> dict:
    names = {}
    for name, key in {**PAPER_METRICS, **EXTRA_METRICS}.items():
        key = key.replace("_last10", f"_last{last_steps}")
        if key in per_step:
            names[name] = key
    if "distance" not in names and "episode/distance" in per_step:  # envs without distance_last10
        names["distance"] = f"episode/distance_last{last_steps}"
    return names


def check_request(policy: Policy, num_envs: int, eval_seeds, stochastic: bool) -> None:
    """ValueError for an impossible evaluation request, ImportError where its intervals cannot be computed (the env
    config is checked where its program is made)."""
    if int(num_envs) < 1:
        raise ValueError(f"num_envs={num_envs!r} is invalid: allowed is an integer >= 1.")
    if not eval_seeds:
        raise ValueError("eval_seeds=[] is invalid: allowed is at least one seed.")
    check_stochastic(policy, stochastic)
    if len(policy.units) * len(eval_seeds) > 1:
        intervals.check_installed()  # the summary's intervals come after the evaluation


def check_stochastic(policy: Policy, stochastic: bool) -> None:
    """ValueError for sampled actions of a policy without an action distribution."""
    if stochastic and policy.export is None:
        raise ValueError(f"stochastic=True is invalid for the {policy.kind} {policy.name!r}: allowed only for checkpoints "
                         f"(the {policy.kind} has no action distribution).")
    if stochastic and policy.planner is not None:
        raise ValueError(f"stochastic=True is invalid for the shielded {policy.name!r}: allowed only for unshielded "
                         "checkpoints (the shield checks the policy's deterministic rollout).")


def run(policy: Policy, env_name: str, env_config, num_envs: int = 4096, eval_seeds=(DEFAULT_EVAL_SEED,),
        last_steps: int = 10, stochastic: bool = False, progress: Callable[[str], None] | None = None,
        allow_env_mismatch: bool = False) -> Result:
    """Evaluates `policy` on `num_envs` episodes per unit and evaluation seed (see module doc); `stochastic=True`
    samples a checkpoint's actions instead of taking its mode; `allow_env_mismatch` evaluates a checkpoint on another
    observation layout or action mode (`check_compatible`) with a warning instead of an error. `progress(line)` is
    told when the program compiles and what each evaluation seed gave."""
    check_request(policy, num_envs, eval_seeds, stochastic)
    program = _program(policy, env_name, env_config, num_envs, last_steps, stochastic, allow_env_mismatch)
    return run_program(policy, program, env_name, env_config, num_envs, eval_seeds, last_steps, stochastic, progress)


def run_program(policy: Policy, program: Program, env_name: str, env_config, num_envs: int, eval_seeds, last_steps: int,
                stochastic: bool, progress: Callable[[str], None] | None) -> Result:
    """`run` with its checked program (`_program`'s, or `agents.sweep`'s): each evaluation seed through `program`."""
    params = act_params(policy)
    batch = len(policy.units) if policy.export else 0
    t0 = time.perf_counter()
    if progress and batch not in program.compiled:
        progress(f"compiling the evaluation of {num_envs} envs x {env_config.episode_length} steps"
                 + (f", {batch} trained seed(s) at once" if batch else "") + " (the first eval seed waits for it) ...")
    units, per_env, seed_seconds = [], {}, []
    for k, eval_seed in enumerate(eval_seeds):
        t_seed = time.perf_counter()
        out = jax.device_get(program.evaluate(params, jax.random.PRNGKey(int(eval_seed)))[0])
        seed_seconds.append(time.perf_counter() - t_seed)
        program.compiled.add(batch)
        names = _metric_names(out, last_steps)
        for i, label in enumerate(policy.units):
            values = {name: np.asarray(out[key][i] if policy.export else out[key], np.float64) for name, key in names.items()}
            units.append({"policy_seed": label, "eval_seed": int(eval_seed),
                          "metrics": {name: float(np.mean(v)) for name, v in values.items()}})
            for name, v in values.items():
                per_env.setdefault(name, []).append(v)
        if progress:
            progress(seed_line(k, len(eval_seeds), eval_seed, units[-len(policy.units):], time.perf_counter() - t0))
    per_env = {k: np.stack(v) for k, v in per_env.items()}
    derived = {**collided_distances(per_env), **reached_precision(per_env)}
    per_env.update(derived)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", RuntimeWarning)
        for i, unit in enumerate(units):
            unit["metrics"].update({name: float(np.nanmean(v[i])) for name, v in derived.items()})
    return Result(policy, env_name, env_config, int(num_envs), [int(s) for s in eval_seeds], int(last_steps), units,
                  per_env, time.perf_counter() - t0, seed_seconds, bool(stochastic))


# ------------------------------------------------------------------------------------------------
# Reporting


COLUMNS = [("target_reached", "target reached", 3), ("self_collision", "self collision", 3),
           ("obstacle_collision", "obstacle collision", 3), ("distance", "distance (m)", 3),
           ("steps_in_target", "steps in target", 1), ("times_left_target", "times left target", 2)]
EXTRA_COLUMNS = [("mean_joint_vel", "mean joint speed (rad/s)", 2),
                 ("mean_joint_acc", "mean joint acceleration (rad/s²)", 1)]
"""(name, header, decimals) of the `EXTRA_METRICS` a results table may show (tools.experiments), beside `COLUMNS`."""


def label(result: Result) -> str:
    p = result.policy
    if p.export is None:
        return p.name
    mode = (", stochastic" if result.stochastic else "") + (f", {p.compute_dtype}" if p.compute_dtype else "")
    if p.planner is not None:
        mode += f", shielded: {p.planner.samples} samples x {p.planner.horizon} steps"
    return f"{p.name} ({p.export.config.algo_name}, {p.export.env_steps:,} steps{mode})"


def markdown(results: list[Result], spread: str = "std_units") -> str:
    """A markdown table, one row per result (plus a pooled row for several checkpoints on one env
    config); mean ± sample standard deviation over units (seeds / checkpoints) and the mean's 95 % confidence
    interval."""
    names = [c for c in COLUMNS if any(c[0] in r.per_env for r in results)]
    head = ["policy", "env", "seeds x envs"] + [c[1] for c in names]
    lines = ["| " + " | ".join(head) + " |", "|" + "---|" * len(head)]
    for r in results:
        s = r.summary()
        cells = [label(r), r.env_name, f"{len(r.units)} x {r.num_envs}"] + [fmt(s.get(n), d, spread, ci=True)
                                                                            for n, _, d in names]
        lines.append("| " + " | ".join(cells) + " |")
    if len(results) > 1 and all(r.policy.export for r in results):
        s = pooled(results)
        if s is not None:
            units = sum(len(r.units) for r in results)
            cells = ["all checkpoints", results[0].env_name, f"{units} x {results[0].num_envs}"]
            lines.append("| " + " | ".join(cells + [fmt(s.get(n), d, spread, ci=True) for n, _, d in names]) + " |")
    return "\n".join(lines)


def _physics_backend(env_config) -> str | None:
    """The backend that stepped the physics (an arm config's `backend` resolved; None for envs without one)."""
    backend = getattr(env_config, "backend", None)
    return physics.resolve(backend) if backend is not None else None


# ------------------------------------------------------------------------------------------------
# Rollouts for rendering


def rollout(policy: Policy, env_name: str, env_config, num_envs: int = 1, eval_seed: int = DEFAULT_EVAL_SEED,
            unit: int = 0, stochastic: bool = False, allow_env_mismatch: bool = False) -> dict:
    """Joint positions, target and obstacle of each env's first episode (for `envs.render`):
    {"qpos": (T + 1, n, nq), "target_pos": ..., ["obstacle_pos": ..., "obstacle_radius": ...], "length": (n,),
    "metrics": {...}}
    with the policy's unit `unit` (a trained seed's index); the episodes that `run` evaluates with as
    many envs, the same seed and the same `stochastic`."""
    program = _program(policy, env_name, env_config, num_envs, 10, stochastic, allow_env_mismatch)
    if policy.export:
        params = jax.tree.map(lambda x: x[unit:unit + 1], policy.export.state)
        out, records = jax.device_get(program.evaluate(params, jax.random.PRNGKey(int(eval_seed))))
        out = {k: v[0] for k, v in out.items()}
        records = jax.tree.map(lambda x: x[0], records)
        program.compiled.add(1)
    else:
        out, records = jax.device_get(program.evaluate(act_params(policy), jax.random.PRNGKey(int(eval_seed))))
        program.compiled.add(0)
    records = {k: np.asarray(v) for k, v in records.items()}
    records["length"] = np.asarray(out["episode/length"]).astype(int)
    records["metrics"] = {k: np.asarray(v) for k, v in out.items()}
    return records
