"""The run's config (`TrainConfig`), its validation and its JSON round trip.

A run's config is stored with every checkpoint and policy export; `config_from_json` rebuilds it
(the algorithm's config class comes from `agents.registry` by the stored `algo_name`).
"""

from __future__ import annotations

import dataclasses
import importlib.util
import json
import math
import re
import types
import typing
import warnings
from typing import Any, Generic, Literal, TypeVar

import jax

import envs
from envs.validation import INT32_MAX, in_range, integer
from agents import registry
from agents.loop import MULTI_DEVICE_MODES

EnvConfigT = TypeVar("EnvConfigT")
AlgoConfigT = TypeVar("AlgoConfigT")
PRECISIONS = ("default", "high", "highest")
LOGGERS = ("csv", "wandb")
WANDB_MODES = ("offline", "online", "disabled")
WANDB_EXTRA = 'pip install -e ".[wandb]"'
"""What installs the wandb package that `logger="wandb"` needs (the project's `wandb` extra)."""


@dataclasses.dataclass(frozen=True)
class TrainConfig(Generic[EnvConfigT, AlgoConfigT]):
    """One training run. `train.py` builds it from a preset plus command-line overrides."""

    env: EnvConfigT
    """Options of the environment (its config dataclass, `--env.<field>` on the command line)."""
    algo: AlgoConfigT
    """Algorithm hyperparameters: a config class registered in agents.registry (PPOConfig, SACConfig)."""
    env_name: str = "point-mass"
    """Registered environment name (see envs.names())."""
    preset: str = ""
    """Name of the preset this config started from (informational)."""
    num_timesteps: int = 1_000_000
    """Environment steps per seed (rounded up to whole updates)."""
    seed: int = 0
    """Seed of the first run; the runs of --seeds N use seed, seed + 1, ..., seed + N - 1."""
    seeds: int = 1
    """Independent runs trained together in one compiled program (vmapped)."""
    devices: int = 0
    """Local devices to split the environments over (0 = all)."""
    episode_restarts: Literal["fresh", "first"] = "fresh"
    """How a training env starts its next episode: fresh (a newly sampled start pose, target and obstacle) or
    first (that env's first initial state again: Brax's and MuJoCo Playground's auto-reset, with which the paper
    trained, so training sees only num_envs distinct episodes; results/fidelity). Evaluation always samples."""
    multi_device: Literal["shard_map", "gspmd"] = "gspmd"
    """How several devices share the work: gspmd (the one-device program under jit with sharded env
    axes; XLA inserts the collectives) or shard_map (each device runs the chunk on its envs; the
    learners average gradients explicitly). Same results up to float rounding; ignored on one device.
    gspmd is the default because XLA's GPU compiler crashed on the shard_map program of the MJX arms."""
    logdir: str = ""
    """Output directory ("" = runs/<preset>/<date-time>)."""
    resume: bool = False
    """Continue from the newest intact checkpoint in logdir, with the config stored there: train.py takes
    the options not typed from it (but the call's own: logdir, stop_after_*, devices, progress); a typed option
    must equal the stored one, except the run-control ones (num_timesteps may grow)."""
    overwrite: bool = False
    """Start afresh in a logdir that holds an earlier run (checkpoints, config.json, metrics.csv, eval.json, tb/):
    its files wait in an aside folder until the new run saves its first checkpoint, then are deleted (a new run
    that fails before puts them back). Without it (or --resume) such a logdir is refused."""
    checkpoint_every: int = 0
    """Save a checkpoint every this many env steps (0 = only at the end)."""
    keep_checkpoints: int = 3
    """Newest checkpoints kept on disk."""
    checkpoint_envs: bool = True
    """Store the environments' states in checkpoints, so --resume continues every episode exactly
    (a resumed run then ends with the parameters of an unbroken one). False keeps checkpoints to the
    learner, RNG and step count and leaves out the learner's transient fields (SAC's replay buffer):
    a resume then starts fresh episodes and SAC refills its buffer with min_replay_size random steps
    first. Smaller checkpoints, for moving runs between machines."""
    log_every: int = 0
    """Log every this many env steps (0 = 50 times per run)."""
    stop_after_steps: int = 0
    """Checkpoint and stop once this many env steps are done (0 = run to num_timesteps); continue
    later with --resume (for time-limited jobs)."""
    stop_after_seconds: float = 0.0
    """Checkpoint and stop before this many seconds from the start (compilation included) have passed:
    a chunk of updates starts only if it ends in time at the last chunk's speed (0 = no limit; the
    first chunk's time includes compilation, so the second is judged conservatively). The final
    evaluation is not counted: keep time for it. Continue later with --resume."""
    stop_at_success: float = 0.0
    """Stop early, and evaluate, once every seed's training episodes reach this success rate: the share of
    episodes that reached the target among those finished since the last log (checked at every log, so
    `log_every` sets how often); 0 = never. The final evaluation then measures the policy on fresh episodes."""
    eval_envs: int = 4096
    """Environments of the final deterministic evaluation (one episode each; 0 = no evaluation)."""
    eval_seed: int = 1_000_000
    """Seed of the evaluation episodes (the same episodes for every seed and checkpoint)."""
    eval_last_steps: int = 10
    """The evaluation also reports each metric averaged over an episode's last this many steps."""
    compile_eval_ahead: bool = True
    """On a GPU or TPU, compile the final evaluation in a thread while the run trains (after its first chunk), so it
    runs at once at the end; only for runs set to end with it (no stop_after_steps or stop_after_seconds). False
    compiles it at the end: for runs near the device's memory limit (compiling tunes kernels on the device) or
    timings of training alone."""
    matmul_precision: Literal["default", "high", "highest"] = "default"
    """float32 matmul precision: "default" lets NVIDIA GPUs use TF32 (fast, ~1e-3 relative error),
    "highest" computes in full float32. Stored with the run so results state what they used."""
    tensorboard: bool = True
    """Write TensorBoard event files (needs tensorboardX)."""
    progress: bool = True
    """Print a progress line."""
    logger: Literal["csv", "wandb"] = "csv"
    """Where metrics go besides metrics.csv (and TensorBoard, see tensorboard): "csv" nowhere else, "wandb" also to
    Weights & Biases, one W&B run per seed with the config and the final evaluation (needs the wandb extra)."""
    wandb_mode: Literal["offline", "online", "disabled"] = "offline"
    """W&B mode with logger="wandb": "offline" writes the runs to logdir/wandb only (upload later with `wandb sync`),
    "online" uploads while training (needs `wandb login`), "disabled" makes the W&B calls no-ops."""
    wandb_project: str = "reach-avoid-bench"
    """W&B project of the runs with logger="wandb"."""

    @property
    def algo_name(self) -> str:
        return registry.of_config(self.algo).name


RUN_FIELDS = ("num_timesteps", "devices", "multi_device", "logdir", "resume", "overwrite", "checkpoint_every", "keep_checkpoints",
              "checkpoint_envs", "log_every", "stop_after_steps", "stop_after_seconds", "stop_at_success", "eval_envs", "eval_seed", "eval_last_steps",
              "compile_eval_ahead",
              "tensorboard", "progress", "logger", "wandb_mode", "wandb_project")
"""Fields that may differ between a checkpoint's config and a resuming command line."""


def num_devices(config: TrainConfig) -> int:
    return config.devices or jax.local_device_count()


def env_steps_per_update(config: TrainConfig) -> int:
    return config.algo.env_steps_per_update


def total_updates(config: TrainConfig) -> int:
    return math.ceil(config.num_timesteps / env_steps_per_update(config))


def _check_multiplier_start(config: TrainConfig) -> None:
    """A delayed PPO-Lagrangian multiplier must act on some update: its first step follows the first update that
    begins at or after `multiplier_start`, and only the updates after that step see it."""
    start = getattr(config.algo, "multiplier_start", 0)
    if not start:
        return
    per_update = env_steps_per_update(config)
    latest = max(total_updates(config) - 2, 0) * per_update
    if start > latest:
        raise ValueError(f"algo.multiplier_start={start} is invalid with num_timesteps={config.num_timesteps}: the "
                         f"multiplier would act on no update; allowed is at most {latest} (whole updates of "
                         f"{per_update} env steps, two before the run's end).")


def validate(config: TrainConfig) -> None:
    """Raises a ValueError naming the field, the value and what is allowed; compiles nothing."""
    registry.of_config(config.algo)
    envs.registry.spec(config.env_name)  # unknown name -> ValueError listing the names
    expected = type(envs.default_config(config.env_name))
    if type(config.env) is not expected:
        raise ValueError(f"env={type(config.env).__name__} does not fit env_name={config.env_name!r}: allowed is {expected.__name__}.")
    available = jax.local_device_count()
    if not 0 <= config.devices <= available:
        raise ValueError(f"devices={config.devices} is invalid: allowed are 0 (all) to {available} (local devices).")
    validate_stored(config, num_devices(config))
    if getattr(config.algo, "failure_budget", None) is not None and getattr(config.env, "success", None) == "reach_and_terminate":
        raise ValueError(f"algo.failure_budget={config.algo.failure_budget!r} is invalid with "
                         "env.success='reach_and_terminate': the budget counts terminations as failures, and there "
                         "reaching terminates too; allowed is env.success='reach_and_stay' (or no budget).")
    for name, low in (("num_timesteps", 1), ("seeds", 1), ("keep_checkpoints", 1), ("eval_last_steps", 1),
                      ("checkpoint_every", 0), ("log_every", 0), ("stop_after_steps", 0), ("eval_envs", 0)):
        if int(getattr(config, name)) < low:
            raise ValueError(f"{name}={getattr(config, name)!r} is invalid: allowed is an integer >= {low}.")
    _check_multiplier_start(config)
    for name in ("seeds", "keep_checkpoints", "eval_last_steps", "eval_envs"):  # array sizes and counts in JAX
        integer(name, int(getattr(config, name)), 0)
    for name in ("seed", "eval_seed"):  # PRNG seeds, int32 inside JAX
        integer(name, getattr(config, name), -INT32_MAX - 1)
    if config.seed + config.seeds - 1 > INT32_MAX:
        raise ValueError(f"seed={config.seed} is invalid with seeds={config.seeds}: allowed is seed <= "
                         f"{INT32_MAX - config.seeds + 1} (the last run's seed, seed + seeds - 1, is an int32).")
    spu = env_steps_per_update(config)
    for name in ("num_timesteps", "checkpoint_every", "log_every", "stop_after_steps"):  # counted in int32 updates
        if math.ceil(int(getattr(config, name)) / spu) > INT32_MAX:
            raise ValueError(f"{name}={getattr(config, name)!r} is invalid: allowed is at most "
                             f"{INT32_MAX * spu:,} env steps ({INT32_MAX:,} updates "
                             f"of {spu:,}: the update counter is int32, as JAX computes).")
    in_range("stop_at_success", config.stop_at_success, 0.0, 1.0)
    if not config.stop_after_seconds >= 0:  # also refuses NaN
        raise ValueError(f"stop_after_seconds={config.stop_after_seconds!r} is invalid: allowed is a number >= 0 "
                         "(0 = no limit).")
    if config.preset and (not re.fullmatch(r"[A-Za-z0-9][A-Za-z0-9._-]*", config.preset) or ".." in config.preset):
        raise ValueError(f"preset={config.preset!r} is invalid: allowed is a name of letters, digits, '.', '_' and '-' "
                         "(it names the default logdir, runs/<preset>/<date-time>).")
    if config.multi_device not in MULTI_DEVICE_MODES:
        raise ValueError(f"multi_device={config.multi_device!r} is unknown: allowed are {', '.join(MULTI_DEVICE_MODES)}.")
    if config.episode_restarts not in envs.wrappers.RESTARTS:
        raise ValueError(f"episode_restarts={config.episode_restarts!r} is unknown: allowed are "
                         f"{', '.join(envs.wrappers.RESTARTS)}.")
    if not isinstance(config.compile_eval_ahead, bool):
        raise ValueError(f"compile_eval_ahead={config.compile_eval_ahead!r} is invalid: allowed are True, False.")
    if config.matmul_precision not in PRECISIONS:
        raise ValueError(f"matmul_precision={config.matmul_precision!r} is unknown: allowed are {', '.join(PRECISIONS)}.")
    validate_logging(config)
    if config.resume and not config.logdir:
        raise ValueError("logdir='' is invalid with resume=True: allowed is the directory of the run to continue.")
    if config.resume and config.overwrite:
        raise ValueError("overwrite=True is invalid with resume=True: allowed is one of them (--resume continues the "
                         "run in logdir, --overwrite replaces it with a fresh one).")


def validate_stored(config: TrainConfig, devices: int = 1) -> None:
    """The part of `validate` that a stored run's config (a checkpoint's) must pass to rebuild its programs here: its
    env and algorithm configs, on `devices` devices (a restore replaces the run fields, such as the device count)."""
    envs.registry.check_config(config.env_name, config.env)
    config.algo.validate(devices)


def validate_logging(config: TrainConfig) -> None:
    """The logger fields of `validate`; with logger="wandb" also that wandb is installed, so a missing package
    stops the run before anything compiles."""
    if config.logger not in LOGGERS:
        raise ValueError(f"logger={config.logger!r} is unknown: allowed are {', '.join(LOGGERS)}.")
    if config.wandb_mode not in WANDB_MODES:
        raise ValueError(f"wandb_mode={config.wandb_mode!r} is unknown: allowed are {', '.join(WANDB_MODES)}.")
    if not 1 <= len(config.wandb_project) <= 128 or any(c in config.wandb_project for c in "/\\#?%:"):
        raise ValueError(f"wandb_project={config.wandb_project!r} is invalid: allowed is a name of 1 to 128 "
                         "characters without / \\ # ? % : (W&B's rule for project names).")
    if config.logger == "wandb" and importlib.util.find_spec("wandb") is None:
        raise ValueError("logger='wandb' needs the wandb package, which is not installed: allowed is logger='csv', "
                         f"or install it with `{WANDB_EXTRA}`.")


# ----------------------------------------------------------------------------------------------
# JSON round trip.


def config_to_dict(config) -> dict:
    """A JSON-ready dict of a (nested) frozen-dataclass config."""
    return json.loads(json.dumps(dataclasses.asdict(config)))


def dataclass_from_dict(cls, data: dict):
    """Inverse of `config_to_dict` for one dataclass type: nested dataclasses and tuples are rebuilt
    from the field annotations; unknown keys raise a ValueError naming them."""
    hints = typing.get_type_hints(cls)
    names = {f.name for f in dataclasses.fields(cls)}
    unknown = sorted(set(data) - names)
    if unknown:
        raise ValueError(f"config field {unknown[0]!r} does not exist in {cls.__name__}: allowed are {', '.join(sorted(names))}.")
    return cls(**{name: _coerce(hints.get(name, Any), value) for name, value in data.items()})


def _coerce(tp, value):
    origin = typing.get_origin(tp)
    if dataclasses.is_dataclass(tp) and isinstance(value, dict):
        return dataclass_from_dict(tp, value)
    if origin is tuple and isinstance(value, list):
        args = typing.get_args(tp)
        inner = args[0] if args else Any
        return tuple(_coerce(inner, v) for v in value)
    if origin in (typing.Union, types.UnionType):
        for arg in typing.get_args(tp):
            if arg is type(None) and value is None:
                return None
        for arg in typing.get_args(tp):
            if arg is not type(None):
                return _coerce(arg, value)
    if tp is float and isinstance(value, int):
        return float(value)
    return value


def config_json(config: TrainConfig) -> dict:
    return {"algo_name": config.algo_name, **config_to_dict(config)}


def config_from_json(data: dict) -> TrainConfig:
    data = dict(data)
    algo_cls = registry.by_name(data.pop("algo_name")).config_cls
    env_cls = type(envs.default_config(data["env_name"]))
    data["env"] = dataclass_from_dict(env_cls, data["env"])
    data["algo"] = dataclass_from_dict(algo_cls, data["algo"])
    return dataclass_from_dict(TrainConfig, data)


def read_config(path: str) -> TrainConfig:
    """The TrainConfig stored in a run's config.json; ValueError naming the file if it cannot be read as one."""
    try:
        with open(path) as f:
            return config_from_json(json.load(f))
    except (ValueError, KeyError, TypeError) as error:
        raise ValueError(f"{path} cannot be read as a run's config ({error!r}): allowed is the config.json that "
                         "train.py wrote.") from error


PER_CALL_FIELDS = ("logdir", "resume", "overwrite", "stop_after_steps", "stop_after_seconds", "devices", "multi_device",
                   "progress")
"""Fields that belong to one train.py call: a resume takes them from the command line, the others from the run."""


def adopt_saved_config(config: TrainConfig, saved: TrainConfig, explicit: set[str]) -> TrainConfig:
    """`config` with every field the command line did not set (`explicit`: dotted names such as
    "algo.learning_rate") taken from the run being resumed, except the `PER_CALL_FIELDS`, so that `--resume`
    needs only the options that change. ValueError if the run was trained from another preset."""
    if saved.preset and config.preset != saved.preset:
        raise ValueError(f"preset={config.preset!r} differs from the resumed run's {saved.preset!r}: allowed on "
                         f"--resume is the run's own preset, {saved.preset!r}.")
    if type(config.env) is not type(saved.env) or type(config.algo) is not type(saved.algo):
        return config  # merge_resume_config names the difference
    changes = {}
    for field in dataclasses.fields(TrainConfig):
        name = field.name
        if name in explicit or name in PER_CALL_FIELDS or name == "preset":
            continue
        mine, theirs = getattr(config, name), getattr(saved, name)
        if dataclasses.is_dataclass(mine):
            keep = {sub.name: getattr(mine, sub.name) for sub in dataclasses.fields(mine) if f"{name}.{sub.name}" in explicit}
            changes[name] = dataclasses.replace(theirs, **keep)
        else:
            changes[name] = theirs
    return dataclasses.replace(config, **changes)


def merge_resume_config(config: TrainConfig, saved: TrainConfig, done_steps: int = 0) -> TrainConfig:
    """The saved config, with only the run-control fields (`RUN_FIELDS`) taken from `config`;
    ValueError naming the first other field that differs, or a num_timesteps below the `done_steps`
    env steps the checkpoint has done. A changed num_timesteps is stored with a warning saying so."""
    for field in dataclasses.fields(TrainConfig):
        if field.name in RUN_FIELDS or field.name == "preset":
            continue
        mine, theirs = getattr(config, field.name), getattr(saved, field.name)
        if mine != theirs:
            if dataclasses.is_dataclass(mine) and type(mine) is type(theirs):
                for sub in dataclasses.fields(mine):
                    if getattr(mine, sub.name) != getattr(theirs, sub.name):
                        raise ValueError(
                            f"{field.name}.{sub.name}={getattr(mine, sub.name)!r} differs from the checkpoint's "
                            f"{getattr(theirs, sub.name)!r}: allowed on --resume is only the checkpoint's value.")
            raise ValueError(f"{field.name}={mine!r} differs from the checkpoint's {theirs!r}: allowed on --resume is only the checkpoint's value.")
    spu = env_steps_per_update(saved)  # runs end on whole updates: a num_timesteps rounds up to one
    if math.ceil(config.num_timesteps / spu) * spu < done_steps:
        raise ValueError(f"num_timesteps={config.num_timesteps} is below the checkpoint's {done_steps} env steps (the "
                         f"stored run's num_timesteps is {saved.num_timesteps}): allowed on --resume is "
                         f"num_timesteps >= {done_steps - spu + 1} (runs end on whole updates of {spu} env steps).")
    if config.num_timesteps != saved.num_timesteps:
        stretched = " The learning-rate schedule is stretched to the new length." if saved.algo.schedule_spans_run else ""
        warnings.warn(f"num_timesteps={config.num_timesteps} differs from the checkpoint's {saved.num_timesteps}: the "
                      f"run continues to {config.num_timesteps} env steps and its config.json now stores that.{stretched}",
                      stacklevel=2)
    return dataclasses.replace(saved, **{f: getattr(config, f) for f in RUN_FIELDS})
