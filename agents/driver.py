"""The Python side of training: config, validation, compiled programs, and the run driver.

`train(config)` runs compiled chunks (`agents.loop`) and, between them, logs (CSV, TensorBoard,
a progress line), checkpoints (`agents.checkpoint`), honours Ctrl-C (checkpoint, then exit) and
stops on a non-finite loss (keeping the last good checkpoint). At the end it evaluates the
deterministic policy and stores the metrics as JSON next to the final checkpoint.
"""

from __future__ import annotations

import contextlib
import csv
import dataclasses
import datetime
import functools
import json
import math
import os
import signal
import sys
import time
import warnings
from typing import Generic, Literal, TypeVar

import jax
import jax.numpy as jnp
import numpy as np

import envs
from agents import export
from agents.checkpoint import Checkpointer, config_to_dict, dataclass_from_dict
from agents.loop import MULTI_DEVICE_MODES, Programs
from agents.ppo import PPO, PPOConfig, learning_rate
from agents.sac import SAC, SACConfig

EnvConfigT = TypeVar("EnvConfigT")
AlgoConfigT = TypeVar("AlgoConfigT")

ALGORITHMS = {"ppo": PPOConfig, "sac": SACConfig}


@dataclasses.dataclass(frozen=True)
class TrainConfig(Generic[EnvConfigT, AlgoConfigT]):
    """One training run. `train.py` builds it from a preset plus command-line overrides."""

    env: EnvConfigT
    """Options of the environment (its config dataclass, `--env.<field>` on the command line)."""
    algo: AlgoConfigT
    """Algorithm hyperparameters: a PPOConfig or a SACConfig."""
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
    multi_device: Literal["shard_map", "gspmd"] = "gspmd"
    """How several devices share the work: gspmd (the one-device program under jit with sharded env
    axes; XLA inserts the collectives) or shard_map (each device runs the chunk on its envs; the
    learners average gradients explicitly). Same results up to float rounding; ignored on one device.
    gspmd is the default because XLA's GPU compiler (jax 0.11.2) crashed on the shard_map program of
    the MJX arms, while gspmd trained them 1.95x faster on 2 H200s than on one (results/archive/lab_notebook.md, "Multi-GPU")."""
    logdir: str = ""
    """Output directory ("" = runs/<preset>/<date-time>)."""
    resume: bool = False
    """Continue from the newest checkpoint in logdir (with the config stored there)."""
    checkpoint_every: int = 0
    """Save a checkpoint every this many env steps (0 = only at the end)."""
    keep_checkpoints: int = 3
    """Newest checkpoints kept on disk."""
    checkpoint_envs: bool = True
    """Store the environments' states in checkpoints, so --resume continues every episode exactly
    (a resumed run then ends with the parameters of an unbroken one). False keeps checkpoints to the
    learner, RNG and step count (5 seeds x 8,192 UR5e envs hold ~0.5 GB of MJX state; the PPO learner
    ~17 MB) and leave out the learner's transient fields (SAC's replay buffer, ~1.2 GB for 5 seeds):
    a resume then starts fresh episodes and SAC refills its buffer with min_replay_size random
    steps first. For moving runs between machines."""
    log_every: int = 0
    """Log every this many env steps (0 = 50 times per run)."""
    stop_after_steps: int = 0
    """Checkpoint and stop once this many env steps are done (0 = run to num_timesteps); continue
    later with --resume (for time-limited jobs)."""
    eval_envs: int = 4096
    """Environments of the final deterministic evaluation (one episode each; 0 = no evaluation)."""
    eval_seed: int = 1_000_000
    """Seed of the evaluation episodes (the same episodes for every seed and checkpoint)."""
    eval_last_steps: int = 10
    """The evaluation also reports each metric averaged over an episode's last this many steps."""
    matmul_precision: Literal["default", "high", "highest"] = "default"
    """float32 matmul precision: "default" lets NVIDIA GPUs use TF32 (fast, ~1e-3 relative error),
    "highest" computes in full float32. Stored with the run so results state what they used."""
    tensorboard: bool = True
    """Write TensorBoard event files (needs tensorboardX)."""
    progress: bool = True
    """Print a progress line."""

    @property
    def algo_name(self) -> str:
        for name, cls in ALGORITHMS.items():
            if isinstance(self.algo, cls):
                return name
        raise ValueError(f"algo={type(self.algo).__name__} is unknown: allowed are {', '.join(c.__name__ for c in ALGORITHMS.values())}.")


# Fields that may differ between a checkpoint's config and a resuming command line.
RUN_FIELDS = ("num_timesteps", "devices", "multi_device", "logdir", "resume", "checkpoint_every", "keep_checkpoints", "checkpoint_envs", "log_every",
              "stop_after_steps", "eval_envs", "eval_seed", "eval_last_steps", "tensorboard", "progress")


class NonFiniteLossError(RuntimeError):
    """A loss became NaN or infinite; the run stopped without saving the broken state."""


def num_devices(config: TrainConfig) -> int:
    return config.devices or jax.local_device_count()


def env_steps_per_update(config: TrainConfig) -> int:
    return config.algo.env_steps_per_update


def total_updates(config: TrainConfig) -> int:
    return math.ceil(config.num_timesteps / env_steps_per_update(config))


def learning_rate_note(config: TrainConfig, env_steps: int) -> str | None:
    """For a PPO run that ends before its decaying learning-rate schedule does: a line saying where the
    learning rate stands. A policy evaluated there has not had the schedule's low-rate end, which matters
    for precise reaching (results/lr_schedule/README.md). None for finished runs and
    schedules that do not decay."""
    algo = config.algo
    if not isinstance(algo, PPOConfig) or algo.lr_schedule == "constant":
        return None
    updates, planned = env_steps // env_steps_per_update(config), total_updates(config)
    if updates >= planned:
        return None
    # The same progress the PPO learner feeds its schedule: updates done / updates planned.
    fraction = float(learning_rate(algo, np.float32(updates / planned))) / algo.learning_rate
    return (f"the learning rate is at {fraction:.0%} of its start: its {algo.lr_schedule} schedule runs to "
            f"--num-timesteps {config.num_timesteps:,}. --resume continues it; for a shorter run, set "
            "--num-timesteps to the steps it will really train.")


def validate(config: TrainConfig) -> None:
    """Raises a ValueError naming the field, the value and what is allowed; compiles nothing."""
    if not isinstance(config.algo, tuple(ALGORITHMS.values())):
        raise ValueError(f"algo={config.algo!r} is invalid: allowed are {', '.join(c.__name__ for c in ALGORITHMS.values())}.")
    envs.registry.spec(config.env_name)  # unknown name -> ValueError listing the names
    expected = type(envs.default_config(config.env_name))
    if type(config.env) is not expected:
        raise ValueError(f"env={type(config.env).__name__} does not fit env_name={config.env_name!r}: allowed is {expected.__name__}.")
    config.env.validate()
    available = jax.local_device_count()
    if not 0 <= config.devices <= available:
        raise ValueError(f"devices={config.devices} is invalid: allowed are 0 (all) to {available} (local devices).")
    config.algo.validate(num_devices(config))
    for name, low in (("num_timesteps", 1), ("seeds", 1), ("keep_checkpoints", 1), ("eval_last_steps", 1),
                      ("checkpoint_every", 0), ("log_every", 0), ("stop_after_steps", 0), ("eval_envs", 0)):
        if int(getattr(config, name)) < low:
            raise ValueError(f"{name}={getattr(config, name)!r} is invalid: allowed is an integer >= {low}.")
    if config.multi_device not in MULTI_DEVICE_MODES:
        raise ValueError(f"multi_device={config.multi_device!r} is unknown: allowed are {', '.join(MULTI_DEVICE_MODES)}.")
    if config.matmul_precision not in ("default", "high", "highest"):
        raise ValueError(f"matmul_precision={config.matmul_precision!r} is unknown: allowed are default, high, highest.")
    if config.resume and not config.logdir:
        raise ValueError("logdir='' is invalid with resume=True: allowed is the directory of the run to continue.")


def default_learner_cls(algo_config) -> type:
    """The learner class of an algorithm config: PPO for a PPOConfig, SAC for a SACConfig."""
    return PPO if isinstance(algo_config, PPOConfig) else SAC


def make_learner(algo_config, observation_size: int, action_size: int, updates: int, learner_cls: type | None = None):
    """The learner for `algo_config`: `learner_cls` (default `default_learner_cls`) called with the
    default class's arguments, `(config, observation_size, action_size, total_updates)` for PPO and
    `(config, observation_size, action_size)` for SAC."""
    cls = learner_cls or default_learner_cls(algo_config)
    if isinstance(algo_config, PPOConfig):
        return cls(algo_config, observation_size, action_size, updates)
    return cls(algo_config, observation_size, action_size)


@functools.lru_cache(maxsize=8)
def build_programs(env_name: str, env_config, algo_config, seeds: int, devices: int, updates: int,
                   eval_envs: int, eval_last_steps: int, learner_cls: type | None,
                   multi_device: str) -> Programs:
    """Compiled programs for one setting; cached so repeated runs (tests, resumes) reuse them. The
    learner class is part of the key: a class redefined (e.g. in a notebook cell) is a new object
    and compiles anew."""
    base = envs.from_config(env_name, env_config)
    env = envs.wrap(base)
    learner = make_learner(algo_config, env.observation_size, env.action_size, updates, learner_cls)
    return Programs(env, env, learner, algo_config.num_envs, seeds, jax.local_devices()[:devices],
                    max(eval_envs, 1), env_config.episode_length, eval_last_steps, multi_device)


def programs_for(config: TrainConfig, learner_cls: type | None = None) -> Programs:
    """The (cached) programs of `config`, with `learner_cls` in place of the default learner class."""
    return build_programs(config.env_name, config.env, config.algo, config.seeds, num_devices(config),
                          total_updates(config), config.eval_envs, config.eval_last_steps,
                          learner_cls or default_learner_cls(config.algo), config.multi_device)


def seed_keys(config: TrainConfig) -> jax.Array:
    return jnp.stack([jax.random.PRNGKey(config.seed + i) for i in range(config.seeds)])


def config_json(config: TrainConfig) -> dict:
    return {"algo_name": config.algo_name, **config_to_dict(config)}


def config_from_json(data: dict) -> TrainConfig:
    data = dict(data)
    algo_cls = ALGORITHMS[data.pop("algo_name")]
    env_cls = type(envs.default_config(data["env_name"]))
    data["env"] = dataclass_from_dict(env_cls, data["env"])
    data["algo"] = dataclass_from_dict(algo_cls, data["algo"])
    return dataclass_from_dict(TrainConfig, data)


def _check_resume_config(config: TrainConfig, saved: TrainConfig) -> TrainConfig:
    """The saved config, with only the run-control fields taken from `config`."""
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
    if config.num_timesteps != saved.num_timesteps and isinstance(saved.algo, PPOConfig) and saved.algo.lr_schedule != "constant":
        warnings.warn("num_timesteps changed on resume: the learning-rate schedule is stretched to the new length.")
    return dataclasses.replace(saved, **{f: getattr(config, f) for f in RUN_FIELDS})


# ----------------------------------------------------------------------------------------------
# Logging.


class _Logger:
    def __init__(self, logdir: str, config: TrainConfig):
        self.config = config
        self.csv_path = os.path.join(logdir, "metrics.csv")
        self.columns = None
        self.writers = []
        if config.tensorboard:
            try:
                from tensorboardX import SummaryWriter
                self.writers = [SummaryWriter(os.path.join(logdir, "tb", f"seed_{config.seed + i}")) for i in range(config.seeds)]
            except ImportError:
                print("tensorboardX is not installed: no TensorBoard logs (CSV only).", file=sys.stderr)
        self.tty = sys.stdout.isatty()
        self.last_len = 0

    def log(self, step: int, metrics: dict, extra: dict) -> None:
        names = sorted(metrics)
        if self.columns is None:
            self.columns = ["env_steps", "seed", *sorted(extra), *names]
            if not os.path.exists(self.csv_path):
                with open(self.csv_path, "w", newline="") as f:
                    csv.writer(f).writerow(self.columns)
        with open(self.csv_path, "a", newline="") as f:
            w = csv.writer(f)
            for i in range(self.config.seeds):
                row = {"env_steps": step, "seed": self.config.seed + i, **extra, **{k: float(metrics[k][i]) for k in names}}
                w.writerow([row.get(c, "") for c in self.columns])
        for i, writer in enumerate(self.writers):
            for k in names:
                writer.add_scalar(k, float(metrics[k][i]), step)
            for k, v in extra.items():
                writer.add_scalar("perf/" + k, v, step)
            writer.flush()

    def progress(self, step: int, total: int, rate: float, metrics: dict) -> None:
        if not self.config.progress:
            return
        eta = datetime.timedelta(seconds=int((total - step) / rate)) if rate > 0 else "?"
        parts = [f"[{self.config.preset or self.config.env_name}] {_si(step)}/{_si(total)} steps ({100 * step / total:.1f}%)",
                 f"{_si(rate)} steps/s", f"ETA {eta}"]
        for k in ["episode/return"] + [k for k in sorted(metrics) if k.startswith("episode/") and k != "episode/return"][:4]:
            if k in metrics:
                parts.append(f"{k.split('/', 1)[1]} {np.nanmean(metrics[k]):.3g}")
        line = " | ".join(parts)
        if self.tty:
            print("\r" + line.ljust(self.last_len), end="", flush=True)
            self.last_len = len(line)
        else:
            print(line, flush=True)

    def close(self) -> None:
        if self.tty and self.config.progress:
            print()
        for w in self.writers:
            w.close()


def _si(x: float) -> str:
    for unit, scale in (("G", 1e9), ("M", 1e6), ("k", 1e3)):
        if abs(x) >= scale:
            return f"{x / scale:.2f}{unit}"
    return f"{x:.0f}"


# ----------------------------------------------------------------------------------------------
# The driver.


@dataclasses.dataclass
class TrainResult:
    state: object
    """The final seed-batched TrainState (on device)."""
    env_steps: int
    status: str
    """"done", "stopped" (stop_after_steps) or "interrupted" (Ctrl-C)."""
    logdir: str
    config: TrainConfig
    eval_metrics: dict | None
    last_metrics: dict | None


def train(config: TrainConfig, learner_cls: type | None = None) -> TrainResult:
    """Runs (or, with `config.resume`, continues) the training run `config` describes.

    `learner_cls` replaces the algorithm's learner class (`PPO` for a PPOConfig, `SAC` for a
    SACConfig), typically a subclass that changes one piece, e.g. `class MyPPO(PPO)` overriding
    `advantages`; it is constructed with the default class's arguments (see `make_learner`) and
    must keep its state type (checkpoints, policy exports). The class is not stored with the run:
    exports act with the default class's `policy`, and a resume must pass the class again.
    """
    validate(config)
    precision = config.matmul_precision
    with contextlib.nullcontext() if precision == "default" else jax.default_matmul_precision(precision):
        return _train(config, learner_cls)


def _train(config: TrainConfig, learner_cls: type | None = None) -> TrainResult:
    logdir = config.logdir or os.path.join("runs", config.preset or config.env_name,
                                           datetime.datetime.now().strftime("%Y%m%d-%H%M%S"))
    config = dataclasses.replace(config, logdir=logdir)
    ckpt = Checkpointer(os.path.join(logdir, "checkpoints"), keep=config.keep_checkpoints)
    start_step = None
    if config.resume:
        start_step = ckpt.latest_step()
        if start_step is None:
            raise ValueError(f"resume=True but logdir={logdir!r} holds no checkpoint: allowed is the directory of an earlier run.")
        saved = config_from_json(ckpt.restore_config(start_step))
        config = _check_resume_config(config, saved)
        validate(config)
    os.makedirs(logdir, exist_ok=True)
    with open(os.path.join(logdir, "config.json"), "w") as f:
        json.dump(config_json(config), f, indent=2)

    programs = programs_for(config, learner_cls)
    spu = env_steps_per_update(config)
    updates_total = total_updates(config)
    if start_step is None:
        state = programs.init(seed_keys(config))
    else:
        state = restore_state(ckpt, start_step, programs, config, with_envs=saved.checkpoint_envs)
    updates_done = int(jax.device_get(state.updates[0]))

    log_every = config.log_every or max(spu, config.num_timesteps // 50)
    every = lambda steps: max(1, steps // spu)
    stop_updates = updates_total
    if config.stop_after_steps:
        stop_updates = min(updates_total, math.ceil(config.stop_after_steps / spu))

    logger = _Logger(logdir, config)
    interrupted = {"flag": False}
    previous_handler = _install_sigint(interrupted)
    last_saved = start_step
    last_metrics = None
    status = "done"
    try:
        while updates_done < stop_updates:
            targets = [stop_updates, (updates_done // every(log_every) + 1) * every(log_every)]
            if config.checkpoint_every:
                targets.append((updates_done // every(config.checkpoint_every) + 1) * every(config.checkpoint_every))
            n = min(targets) - updates_done
            t0 = time.perf_counter()
            state, metrics = programs.chunk(state, jnp.int32(n))
            metrics = jax.device_get(metrics)
            seconds = time.perf_counter() - t0
            updates_done += n
            step = updates_done * spu
            bad = [k for k in metrics if k.startswith("loss/") and not np.all(np.isfinite(metrics[k]))]
            if bad:
                raise NonFiniteLossError(
                    f"{bad[0]} became {metrics[bad[0]].tolist()} (per seed) in the updates ending at env step {step}; "
                    f"training stopped. The last good checkpoint ({last_saved}) is kept in {ckpt.directory}.")
            rate = n * spu * config.seeds / seconds
            logger.log(step, metrics, {"steps_per_second": rate, "wall_seconds": seconds})
            logger.progress(step, updates_total * spu, rate / config.seeds, metrics)
            last_metrics = metrics
            due = config.checkpoint_every and updates_done % every(config.checkpoint_every) == 0
            if due or interrupted["flag"]:
                save_checkpoint(ckpt, step, state, config, programs.learner)
                last_saved = step
            if interrupted["flag"]:
                status = "interrupted"
                break
        step = updates_done * spu
        if status == "done" and updates_done < updates_total:
            status = "stopped"
        if last_saved != step:
            save_checkpoint(ckpt, step, state, config, programs.learner)
            last_saved = step
        eval_metrics = None
        if status == "done" and config.eval_envs > 0:
            eval_metrics = evaluate(programs, state, config)
            text = json.dumps({"env_steps": step, "eval_envs": config.eval_envs, "per_seed": eval_metrics,
                               "mean": {k: float(np.mean(v)) for k, v in eval_metrics.items()}}, indent=2)
            for path in (os.path.join(ckpt.step_dir(step), "eval.json"), os.path.join(logdir, "eval.json")):
                with open(path, "w") as f:
                    f.write(text)
    finally:
        logger.close()
        ckpt.close()
        _restore_sigint(previous_handler)
    return TrainResult(state, updates_done * spu, status, logdir, config, eval_metrics, last_metrics)


def _transient_fields(learner) -> tuple[str, ...]:
    """Learner-state fields that learner-only checkpoints leave out (`Learner.transient_fields`)."""
    return tuple(getattr(learner, "transient_fields", ()))


def _learner_only(state, learner):
    """The state as a learner-only checkpoint stores it: no env states, no transient learner fields."""
    transient = {name: None for name in _transient_fields(learner)}
    return state.replace(learner=state.learner.replace(**transient), env_state=None, episode_return=None,
                         episode_length=None)


def save_checkpoint(ckpt: Checkpointer, step: int, state, config: TrainConfig, learner) -> None:
    """The checkpoint (without env states if `config.checkpoint_envs` is False) plus, next to it, the
    small policy export that eval.py loads (`agents.export`: policy parameters, observation
    statistics, config)."""
    ckpt.save(step, state if config.checkpoint_envs else _learner_only(state, learner), config_json(config))
    export.save(os.path.join(ckpt.step_dir(step), export.DIRNAME), state.learner, config_json(config), step)


def restore_state(ckpt: Checkpointer, step: int, programs: Programs, config: TrainConfig, with_envs: bool):
    """The `TrainState` saved at `step`. A checkpoint saved without env states gets fresh episodes,
    drawn from keys that depend on the seed and the step (not on the start's keys)."""
    if with_envs:
        return ckpt.restore(step, programs.abstract_state)[0]
    saved, _ = ckpt.restore(step, _learner_only(programs.abstract_state, programs.learner))
    fresh = programs.init(jax.vmap(jax.random.fold_in, (0, None))(seed_keys(config), step))
    transient = {name: getattr(fresh.learner, name) for name in _transient_fields(programs.learner)}
    return fresh.replace(learner=saved.learner.replace(**transient), key=saved.key, updates=saved.updates)


def evaluate(programs: Programs, state, config: TrainConfig) -> dict:
    """Deterministic-policy metrics per seed, {name: [value per seed]}."""
    out = programs.evaluate(state.learner, jax.random.PRNGKey(config.eval_seed))
    return {k: np.asarray(v).tolist() for k, v in jax.device_get(out).items()}


def _install_sigint(flag: dict):
    def handler(signum, frame):
        if flag["flag"]:
            raise KeyboardInterrupt
        flag["flag"] = True
        print("\nCtrl-C: saving a checkpoint after the current chunk (press again to abort without saving).",
              file=sys.stderr, flush=True)

    try:
        return signal.signal(signal.SIGINT, handler)
    except ValueError:  # not the main thread
        return None


def _restore_sigint(previous) -> None:
    if previous is not None:
        try:
            signal.signal(signal.SIGINT, previous)
        except ValueError:
            pass
