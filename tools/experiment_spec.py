"""What an experiment is: `Run` (a preset, field overrides, seeds and a budget), `Cross` (a cross-evaluation of
a run's policies) and `Experiment` (runs, table columns, figure curves), the registry `EXPERIMENTS` and
`register`, and the paper's numbers (`paper_table`, `paper_row`: assets/paper_numbers.json). The registered
experiments are gathered by `tools/experiment_registry.py`; `tools/experiments.py` trains, lists and tabulates them.

Only the standard library at the top: the results index reads the registry without importing jax.
"""

from __future__ import annotations

import dataclasses
import functools
import json
import os
from typing import Callable

MANAGED_FIELDS = ("seeds", "num_timesteps", "logdir", "resume", "stop_after_steps", "preset", "env_name", "env", "algo")
"""TrainConfig fields a Run sets itself (or that name other things), never through `overrides`."""

PAPER_NUMBERS = os.path.join(os.path.dirname(os.path.dirname(os.path.abspath(__file__))), "assets", "paper_numbers.json")
"""The paper's numbers that runs and results tables are compared with: one entry per table or paragraph, each
naming the section or table it comes from. Read here because this module is the one jax-free module that both
the registry (`Run.paper`) and the results index import."""


@functools.cache
def _paper_numbers() -> dict:
    with open(PAPER_NUMBERS, encoding="utf-8") as f:
        return json.load(f)


def paper_table(name: str) -> list[dict]:
    """The rows of entry `name` of assets/paper_numbers.json as {column: value}, values the paper does not state
    (null) left out."""
    entry = _paper_numbers()[name]
    return [{c: v for c, v in zip(entry["columns"], row) if v is not None} for row in entry["rows"]]


def paper_row(name: str, **key) -> dict:
    """The paper's means in the one row of entry `name` whose columns equal `key` (e.g. trained="0.1",
    evaluated=0.1), as a `Run.paper`: {metric: value}, without the key columns and the '_std' ones."""
    rows = [r for r in paper_table(name) if all(r.get(k) == v for k, v in key.items())]
    if len(rows) != 1:
        raise KeyError(f"paper_numbers.json: {name} has {len(rows)} rows with {key}: allowed is exactly one.")
    return {c: v for c, v in rows[0].items() if c not in key and not c.endswith("_std")}



@dataclasses.dataclass(frozen=True)
class Run:
    """One training command: a preset, field overrides, seeds and a budget."""

    name: str
    """Folder name under the experiment (letters, digits, '-', '_', '.')."""
    preset: str
    """A preset of agents/presets.py."""
    overrides: dict = dataclasses.field(default_factory=dict)
    """Fields replacing the preset's: "env.<field>", "algo.<field>" or a TrainConfig field (eval_envs, ...)."""
    seeds: int = 5
    """Seeds trained together (5 for the paper's table rows and stated numbers, 3 for curve-only comparisons)."""
    num_timesteps: int | None = None
    """Env steps per seed; None: the preset's."""
    label: str = ""
    """The row's name in the table ("" = `name`)."""
    paper: dict = dataclasses.field(default_factory=dict)
    """The paper's numbers for this run, {metric: value} (rates in [0, 1], distances in m): a `paper_row`."""
    shares: bool = True
    """Whether the run trains in the folder of an earlier registered run with the same training config. False where
    the code under that config has changed the task since that run trained (its parts would be another task's): the
    run keeps its own folder, and later runs of that config share it instead."""

    @property
    def title(self) -> str:
        return self.label or self.name

    def budget(self) -> int:
        """Env steps per seed (the preset's when `num_timesteps` is None)."""
        return self.num_timesteps if self.num_timesteps is not None else self.preset_budget()

    def preset_budget(self) -> int:
        """The preset's env steps per seed (0 for an unknown preset, which validation reports)."""
        from agents.presets import PRESETS

        return PRESETS[self.preset].run.get("num_timesteps", 1_000_000) if self.preset in PRESETS else 0

    def config(self, logdir: str = "", first_seed: int = 0, seeds: int | None = None, **run_fields):
        """The TrainConfig (not validated) of seeds `first_seed` .. `first_seed + seeds - 1` of this run (default:
        all its seeds): preset, overrides, budget, logdir, plus `run_fields`. Seed i of the run trains from
        PRNG seed `seed + i`, so a part of the seeds trains exactly what the whole run would for them."""
        from agents.presets import make_config

        config = apply_overrides(make_config(self.preset), self.overrides)
        return dataclasses.replace(config, seed=config.seed + first_seed, seeds=self.seeds if seeds is None else seeds,
                                   num_timesteps=self.budget(), logdir=logdir, **run_fields)

    def train_args(self, logdir: str, resume: bool = False, first_seed: int = 0, seeds: int | None = None) -> list[str]:
        """train.py's arguments for these seeds (`python train.py <these>` builds `self.config(logdir, ...)`)."""
        count = self.seeds if seeds is None else seeds
        args = [self.preset, "--logdir", logdir, "--seeds", str(count), "--num-timesteps", str(self.budget())]
        for dotted, value in self.overrides.items():
            if dotted != "seed":
                args += cli_option(dotted, value)
        if first_seed or "seed" in self.overrides:
            args += ["--seed", str(self.config(first_seed=first_seed).seed)]
        return args + (["--resume"] if resume else [])


@dataclasses.dataclass(frozen=True)
class Cross:
    """A cross-evaluation: the final policies of one of the experiment's runs on another env setting, or with
    sampled actions (one more table row, as the paper's workspace and obstacle-size tables have)."""

    run: str
    """The trained run (a name among the experiment's runs)."""
    name: str
    """Row name and file name (`cross-<name>.json` beside each part's eval.json): letters, digits, '-', '_', '.'."""
    env: dict
    """Env fields replacing the run's own for this evaluation ({"obstacle_motion": "linear"})."""
    label: str = ""
    """The row's name in the table ("" = "<run> on <name>")."""
    paper: dict = dataclasses.field(default_factory=dict)
    """The paper's numbers for this row (rates in [0, 1], distances in m)."""
    stochastic: bool = False
    """Actions sampled from the policy (`eval.py --stochastic`) instead of its mode: the paper does not say
    which it reports, and for SAC it matters (results/sampled_actions)."""

    @property
    def setting(self) -> str:
        """"obstacle_motion=linear, ..., sampled actions": what it changes, for listings and tables."""
        return ", ".join([f"{k}={v}" for k, v in self.env.items()] + (["sampled actions"] if self.stochastic else []))


@dataclasses.dataclass(frozen=True)
class Experiment:
    """A named set of runs and how their results become a table and a figure."""

    name: str
    """Registry key and folder name."""
    title: str
    """One line: what the experiment compares."""
    paper_ref: str
    """Where the paper has it: table, figure or section ("not in the paper" for our studies)."""
    runs: tuple[Run, ...]
    metrics: tuple[str, ...] = ("target_reached", "self_collision", "distance")
    """Table columns: keys of agents.evaluation.PAPER_METRICS or of its EXTRA_COLUMNS (mean_joint_vel,
    mean_joint_acc), or wall_clock / steps_per_second (metrics.csv)."""
    curves: tuple[str, ...] = ("episode/target_reached", "episode/self_collision")
    """metrics.csv columns drawn in the figure (() = no figure)."""
    curve_groups: tuple[tuple[str, tuple[str, ...]], ...] = ()
    """Rows of the figure, (row title, names of the runs drawn together): runs to compare on shared panels (fast
    SAC and PPO on one task); () = one row of every run."""
    curve_axes: tuple[str, ...] = ("env_steps",)
    """Horizontal axes of the figure's panels, side by side: env_steps and/or wall_clock (CURVE_AXES)."""
    paper: str = ""
    """The paper's finding in one line (shown in the results index)."""
    note: str = ""
    """Where the runs depart from the paper, and what the table leaves to other tools."""
    builder: Callable | None = None
    """builder(experiment, states, out_dir) -> written files; None: `build_default`."""
    cross: tuple[Cross, ...] = ()
    """Cross-evaluations, run where the parts' checkpoints are (after training, or by `build`)."""

    def run(self, name: str) -> Run:
        for r in self.runs:
            if r.name == name:
                return r
        raise ValueError(f"run {name!r} is not in experiment {self.name!r}: allowed are {', '.join(r.name for r in self.runs)}.")


CURVE_AXES = ("env_steps", "wall_clock")
"""Horizontal axes a figure can have (tools.plots.X_AXES)."""

EXPERIMENTS: dict[str, Experiment] = {}


def register(experiment: Experiment, registry: dict | None = None) -> Experiment:
    """Adds `experiment` to the registry (EXPERIMENTS); ValueError on a name used twice."""
    registry = EXPERIMENTS if registry is None else registry
    if experiment.name in registry:
        raise ValueError(f"experiment {experiment.name!r} is registered twice: allowed is one experiment per name.")
    names = [r.name for r in experiment.runs]
    if len(set(names)) != len(names) or not names:
        raise ValueError(f"experiment {experiment.name!r} has runs {names}: allowed are one or more distinct names.")
    for title, group in experiment.curve_groups:
        unknown = [name for name in group if name not in names]
        if unknown or not group:
            raise ValueError(f"experiment {experiment.name!r}: curve_groups row {title!r} names runs {list(group)}: "
                             f"allowed are one or more of {', '.join(names)}.")
    bad = [x for x in experiment.curve_axes if x not in CURVE_AXES] or ([] if experiment.curve_axes else ["()"])
    if bad:
        raise ValueError(f"experiment {experiment.name!r}: curve_axes={experiment.curve_axes!r} holds {bad[0]!r}: "
                         f"allowed are one or more of {', '.join(CURVE_AXES)}.")
    registry[experiment.name] = experiment
    return experiment


def apply_overrides(config, overrides: dict):
    """`config` with dotted overrides ("env.reward", "algo.policy_hidden_sizes", "eval_envs") applied; ValueError
    naming an unknown field. Lists become tuples; values are checked later by agents.config.validate."""
    for dotted, value in overrides.items():
        value = tuple(value) if isinstance(value, list) else value
        head, _, field = dotted.partition(".")
        if field:
            if head not in ("env", "algo") or "." in field:
                raise ValueError(f"override {dotted!r} is invalid: allowed are env.<field>, algo.<field> or a TrainConfig field.")
            sub = getattr(config, head)
            allowed = [f.name for f in dataclasses.fields(sub)]
            if field not in allowed:
                raise ValueError(f"override {dotted!r} is unknown for {type(sub).__name__}: allowed are {', '.join(allowed)}.")
            config = dataclasses.replace(config, **{head: dataclasses.replace(sub, **{field: value})})
        else:
            allowed = [f.name for f in dataclasses.fields(config) if f.name not in MANAGED_FIELDS]
            if head not in allowed:
                raise ValueError(f"override {dotted!r} is invalid: allowed are env.<field>, algo.<field> or one of "
                                 f"{', '.join(allowed)} (seeds and budget are Run fields).")
            config = dataclasses.replace(config, **{head: value})
    return config


def cli_option(dotted: str, value) -> list[str]:
    """train.py's (tyro's) spelling of one override: `--env.w-joint-acc 0.0001`, `--no-tensorboard`,
    `--algo.policy-hidden-sizes 256 256 256`."""
    head, _, field = dotted.rpartition(".")
    prefix = f"--{head}." if head else "--"
    field = field.replace("_", "-")
    if isinstance(value, bool):
        return [prefix + ("" if value else "no-") + field]
    if isinstance(value, (tuple, list)):
        return [prefix + field, *map(str, value)]
    return [prefix + field, str(value)]
