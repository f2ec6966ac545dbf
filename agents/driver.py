"""The training run: compiled programs, the chunk loop, checkpoints and Ctrl-C.

`train(config)` checks the logdir (`agents.logdir`: an earlier run is refused unless `resume` or `overwrite`),
runs compiled chunks (`agents.loop`) and, between them, logs (`agents.logger`; with logger="wandb" also
`agents.wandb_logger`), checkpoints (`agents.checkpoint`, plus the policy export of `agents.export`), honours Ctrl-C
(checkpoint, then exit) and stops on a non-finite learner metric (keeping the last good checkpoint; a resume skips
damaged checkpoints, moving them aside). A fresh run compiles its training chunk while `init` compiles and runs. At
the end it evaluates the deterministic policy (compiled while it trained, on a GPU) and stores the metrics as JSON
next to the final checkpoint. The config and its validation live in
`agents.config`; the algorithm comes from `agents.registry`.
"""

from __future__ import annotations

import contextlib
import dataclasses
import datetime
import functools
import json
import math
import os
import shutil
import signal
import sys
import time
import warnings

import jax
import jax.numpy as jnp
import numpy as np

import envs
from agents import export, provenance, registry
from envs import validation
from agents.ahead import compile_ahead, finish
from agents.checkpoint import Checkpointer, write_atomic
from agents.config import (TrainConfig, config_from_json, config_json, env_steps_per_update, merge_resume_config,
                           num_devices, total_updates, validate, validate_stored)
from agents import logdir as logdirs
from agents.logger import Logger, cut_rows_after
from agents.loop import Programs
from agents.wandb_logger import WandbLogger


class NonFiniteLossError(RuntimeError):
    """A learner metric (a loss, the gradient norm, the KL, ...) became NaN or infinite; the run stopped
    without saving the broken state."""


@functools.lru_cache(maxsize=8)
def build_programs(env_name: str, env_config, algo_config, seeds: int, devices: int, updates: int,
                   eval_envs: int, eval_last_steps: int, learner_cls: type | None,
                   multi_device: str, episode_restarts: str = "fresh") -> Programs:
    """Compiled programs for one setting; cached so repeated runs (tests, resumes) reuse them. The
    learner class is part of the key: a class redefined (e.g. in a notebook cell) is a new object
    and compiles anew."""
    base = envs.registry.build(env_name, env_config)  # checked by the caller (see `programs_for`)
    env, eval_env = envs.wrap(base, restarts=episode_restarts), envs.wrap(base)  # evaluation always samples
    learner = registry.make_learner(algo_config, env.observation_size, env.action_size, updates, learner_cls)
    return Programs(env, eval_env, learner, algo_config.num_envs, seeds, jax.local_devices()[:devices],
                    max(eval_envs, 1), env_config.episode_length, eval_last_steps, multi_device)


def programs_for(config: TrainConfig, learner_cls: type | None = None) -> Programs:
    """The (cached) programs of `config`, with `learner_cls` in place of the registered learner class; `config` is
    trusted: checked by `validate` (a run) or `validate_stored` (a checkpoint's config)."""
    return build_programs(config.env_name, config.env, config.algo, config.seeds, num_devices(config),
                          total_updates(config), config.eval_envs, config.eval_last_steps,
                          learner_cls or registry.of_config(config.algo).learner_cls, config.multi_device,
                          config.episode_restarts)


def seed_keys(config: TrainConfig) -> jax.Array:
    return jnp.stack([jax.random.PRNGKey(config.seed + i) for i in range(config.seeds)])


@dataclasses.dataclass
class TrainResult:
    state: object
    """The final seed-batched TrainState (on device)."""
    env_steps: int
    status: str
    """"done", "stopped" (stop_after_steps or stop_after_seconds) or "interrupted" (Ctrl-C or SIGUSR2: `STOP_SIGNALS`)."""
    logdir: str
    config: TrainConfig
    eval_metrics: dict | None
    last_metrics: dict | None
    note: str | None = None
    """The learner's remark on where the run stopped (e.g. a learning-rate schedule not yet at its end)."""


def train(config: TrainConfig, learner_cls: type | None = None) -> TrainResult:
    """Runs (or, with `config.resume`, continues) the training run `config` describes.

    `learner_cls` replaces the algorithm's registered learner class, typically a subclass that
    changes one piece, e.g. `class MyPPO(PPO)` overriding `loss`; it is constructed with the same
    arguments (`agents.registry.make_learner`) and must keep its state type (checkpoints, policy
    exports). The class is not stored with the run: exports act with the registered class's
    `policy`, and a resume must pass the class again.
    """
    validate(config)
    precision = config.matmul_precision
    with contextlib.nullcontext() if precision == "default" else jax.default_matmul_precision(precision):
        return _train(config, learner_cls)


def out_of_time(config: TrainConfig, started: float, per_update: float | None, n: int) -> bool:
    """True if a chunk of `n` updates at `per_update` seconds each would end past `stop_after_seconds`
    (counted from `started`, time.perf_counter); the first chunk, of unknown speed, always runs."""
    if not config.stop_after_seconds or per_update is None:
        return False
    return time.perf_counter() - started + n * per_update > config.stop_after_seconds


def evaluates_ahead(config: TrainConfig, stop_updates: int, updates_total: int) -> bool:
    """Whether the final evaluation compiles in a thread while the run trains (`compile_eval_ahead`): on an accelerator
    (on a CPU the thread would take the training's cores), when the run is to end with its evaluation."""
    return (config.compile_eval_ahead and config.eval_envs > 0 and stop_updates == updates_total
            and not config.stop_after_seconds and jax.default_backend() != "cpu")


def _train(config: TrainConfig, learner_cls: type | None = None) -> TrainResult:
    started = time.perf_counter()
    logdir = config.logdir or os.path.join("runs", config.preset or config.env_name,
                                           datetime.datetime.now().strftime("%Y%m%d-%H%M%S"))
    config = dataclasses.replace(config, logdir=logdir)
    prepared = logdirs.prepare(logdir, config.resume, config.overwrite)  # refusals before anything is written
    created = prepared.created
    ckpt = Checkpointer(os.path.join(logdir, "checkpoints"), keep=config.keep_checkpoints)
    start_step, chunk_ahead = None, None
    try:
        if config.resume:
            ckpt, start_step, config, programs, state = _resume(ckpt, config, learner_cls)
            cut = cut_rows_after(os.path.join(logdir, "metrics.csv"), start_step)
            if cut:
                print(f"metrics.csv: {cut} row(s) logged after the checkpoint at env step {start_step} were dropped; "
                      "the resumed run logs those steps again.", file=sys.stderr)
        else:
            programs = programs_for(config, learner_cls)
            keys = seed_keys(config)
            chunk_ahead = programs.chunk_ahead(keys)
            state = programs.init(keys)
            fallback = getattr(state.env_state, "metrics", {}).get("reset_fallback")
            if fallback is not None:  # options whose samplers cannot succeed: refused before any training
                validation.resets_succeed(config.env_name, config.env, envs.default_config(config.env_name),
                                          jax.device_get(fallback))
        write_atomic(os.path.join(logdir, "config.json"), json.dumps(config_json(config), indent=2))
        sinks = [WandbLogger(config)] if config.logger == "wandb" else []
    except BaseException:
        ckpt.close()
        _undo_start(logdir, prepared)
        finish(chunk_ahead)
        raise
    spu = env_steps_per_update(config)
    updates_total = total_updates(config)
    updates_done = int(jax.device_get(state.updates[0]))

    log_every = config.log_every or max(spu, config.num_timesteps // 50)
    every = lambda steps: max(1, steps // spu)
    stop_updates = updates_total
    if config.stop_after_steps:
        stop_updates = min(updates_total, math.ceil(config.stop_after_steps / spu))

    logger = Logger(logdir, config.seed, config.seeds, config.preset or config.env_name, config.tensorboard,
                    config.progress, sinks)
    interrupted = {"flag": False}
    previous_handler = _install_sigint(interrupted)
    last_saved = start_step
    last_metrics, ahead = None, None  # ahead: the final evaluation compiling in a thread (evaluates_ahead)
    per_update = None  # seconds per update of the last chunk, compilation left out
    # With a time limit the chunk is compiled ahead (jit keeps the executable), so that the first chunk's speed
    # is not mistaken for the compilation's: judged by it, a run started with less than twice its compile time
    # left would stop after one chunk. The first chunk's logged time includes its compiling, less the part that ran
    # beside init (`chunk_ahead`).
    status = "done"
    try:
        timed = config.stop_after_seconds and updates_done < stop_updates  # a resume to evaluate runs no chunk
        t0 = time.perf_counter()
        if chunk_ahead is not None:
            chunk_ahead.join()
        compile_seconds = time.perf_counter() - t0 + (compile_ahead(programs, state) if timed else 0.0)
        first_chunk = True
        while updates_done < stop_updates:
            targets = [stop_updates, (updates_done // every(log_every) + 1) * every(log_every)]
            if config.checkpoint_every:
                targets.append((updates_done // every(config.checkpoint_every) + 1) * every(config.checkpoint_every))
            n = min(targets) - updates_done
            if out_of_time(config, started, per_update, n):
                break
            t0 = time.perf_counter()
            state, metrics = programs.chunk(state, jnp.int32(n))
            if first_chunk and evaluates_ahead(config, stop_updates, updates_total):  # placed as the chunk places it
                ahead = programs.evaluation_ahead(state.learner)
            metrics = jax.device_get(metrics)
            seconds = time.perf_counter() - t0
            per_update = seconds / n
            compiled, first_chunk = first_chunk, False  # its time includes compiling (ahead, or in the call)
            seconds, compile_seconds = seconds + compile_seconds, 0.0
            updates_done += n
            step = updates_done * spu
            bad = nonfinite_learner_metrics(metrics)
            if bad:
                raise NonFiniteLossError(_nonfinite_message(bad, metrics, step, last_saved, ckpt.directory, logdir,
                                                            removed=created and last_saved is None))
            rate = n * spu * config.seeds / seconds
            logger.log(step, metrics, {"steps_per_second": rate, "wall_seconds": seconds})
            logger.progress(step, updates_total * spu, rate / config.seeds, metrics, compiled=compiled)
            last_metrics = metrics
            if succeeded(config, metrics):
                logger.say(f"[{logger.label}] every seed's training episodes reached the target at least "
                           f"{config.stop_at_success:.0%} of the time (stop_at_success): stopping at {step:,} env steps")
                break
            due = config.checkpoint_every and updates_done % every(config.checkpoint_every) == 0
            if due or interrupted["flag"]:
                save_checkpoint(ckpt, step, state, config, programs.learner)
                last_saved = step
                _keep_new_run(prepared)
            if interrupted["flag"]:
                status = "interrupted"
                break
        step = updates_done * spu
        if status == "done" and updates_done < updates_total and not succeeded(config, last_metrics):
            status = "stopped"
        if last_saved != step:
            save_checkpoint(ckpt, step, state, config, programs.learner)
            last_saved = step
        _keep_new_run(prepared)
        eval_metrics = None
        if status == "done" and config.eval_envs > 0:
            logger.say(f"[{logger.label}] evaluating the deterministic policy: {config.eval_envs} episodes per seed"
                       f"{' (compiled while training)' if ahead else ' (compiled on first use)'} ...")
            t0 = time.perf_counter()
            if ahead is not None:
                ahead.join()
            eval_metrics = evaluate(programs, state, config)
            logger.say(f"[{logger.label}] evaluation done in {time.perf_counter() - t0:.0f} s")
            # What made it (command, code, device, date); tables show the device beside speeds, which compare only
            # on one GPU model.
            made = provenance.stamp()
            text = json.dumps({"env_steps": step, "eval_envs": config.eval_envs, "device": made["device"],
                               "provenance": made, "per_seed": eval_metrics,
                               "mean": {k: float(np.mean(v)) for k, v in eval_metrics.items()}}, indent=2)
            for path in (os.path.join(ckpt.step_dir(step), "eval.json"), os.path.join(logdir, "eval.json")):
                write_atomic(path, text)
            logger.log_eval(step, eval_metrics)
    except NonFiniteLossError:
        if last_saved is None:  # nothing worth keeping: no half-made run, and an overwritten one back in place
            logger.close()
            ckpt.close()
            _undo_start(logdir, prepared)
        raise
    finally:
        logger.close()
        ckpt.close()
        _restore_sigint(previous_handler)
        finish(ahead, chunk_ahead)  # a run that ends early waits for its compiles
    note = programs.learner.progress_note(updates_done)
    return TrainResult(state, updates_done * spu, status, logdir, config, eval_metrics, last_metrics, note)


def _undo_start(logdir: str, prepared: logdirs.Prepared) -> None:
    """A run that failed before its first checkpoint: the earlier run it was to replace goes back in place, or the
    directory it created goes."""
    if prepared.aside:
        logdirs.restore_aside(logdir, prepared.aside)
        prepared.aside = None
    elif prepared.created:
        logdirs.remove_run_files(logdir, remove_dir=True)


def _keep_new_run(prepared: logdirs.Prepared) -> None:
    """The new run saved a checkpoint: the earlier run it replaces (overwrite) is deleted now."""
    if prepared.aside:
        logdirs.discard_aside(prepared.aside)
        prepared.aside = None


def _newest_intact(ckpt: Checkpointer, prepare, load):
    """The newest checkpoint of `ckpt` whose config and state both read, newest first: `prepare(step, saved_config)`
    builds what loading needs (its errors propagate: they are not damage), `load(step, prepared)` restores the
    state. Returns (step, prepared, state, [(step, error) of each damaged newer checkpoint]); step None if none
    reads."""
    bad = []
    for step in sorted(ckpt.manager.all_steps(), reverse=True):
        try:
            saved = config_from_json(ckpt.restore_config(step))
        except Exception as error:  # orbax / tensorstore / json raise many types on a damaged file
            bad.append((step, error))
            continue
        prepared = prepare(step, saved)
        try:
            state = load(step, prepared)
        except Exception as error:
            bad.append((step, error))
            continue
        return step, prepared, state, bad
    return None, None, None, bad


def _damage_report(ckpt: Checkpointer, bad) -> str:
    """The damaged checkpoints of `_newest_intact`, one "dir: error" each, for an error message."""
    return "; ".join(f"{ckpt.step_dir(s)}: {_first_line(e)}" for s, e in bad) or "none found"


def _resume(ckpt: Checkpointer, config: TrainConfig, learner_cls):
    """(checkpointer, step, merged config, programs, state) of the newest intact checkpoint. A
    checkpoint that cannot be read is moved to `<logdir>/corrupt_checkpoints/` with a warning naming
    it (so the resumed run can save that step again); ValueError if none is intact."""
    def prepare(step, saved):
        merged = merge_resume_config(config, saved, done_steps=step)  # a refused option is not damage
        validate(merged)
        return merged, saved, programs_for(merged, learner_cls)

    def load(step, prepared):
        merged, saved, programs = prepared
        return restore_state(ckpt, step, programs, merged, with_envs=saved.checkpoint_envs)

    step, prepared, state, bad = _newest_intact(ckpt, prepare, load)
    if step is None:
        raise ValueError(f"resume=True but logdir={config.logdir!r} holds no intact checkpoint "
                         f"({_damage_report(ckpt, bad)}): allowed is the directory of an earlier run with at least "
                         "one readable checkpoint.")
    merged, _, programs = prepared
    if bad:
        aside = os.path.join(config.logdir, "corrupt_checkpoints")
        os.makedirs(aside, exist_ok=True)
        for s, error in bad:
            target = os.path.join(aside, str(s))
            if os.path.exists(target):
                shutil.rmtree(target)
            shutil.move(ckpt.step_dir(s), target)
            warnings.warn(f"checkpoint {ckpt.step_dir(s)} is damaged ({_first_line(error)}); moved to {target}. "
                          f"Resuming from the newest intact one, env step {step}.", stacklevel=3)
        ckpt.close()  # the manager lists the steps it found when it was made
        ckpt = Checkpointer(ckpt.directory, keep=config.keep_checkpoints)
    return ckpt, step, merged, programs, state


def _first_line(error: BaseException) -> str:
    text = str(error).strip().splitlines()
    first = text[0].split(" See full TensorStore details")[0] if text else ""  # the rest is a C++ repr
    return f"{type(error).__name__}: {first}"


def nonfinite_learner_metrics(metrics: dict) -> list[str]:
    """The learner metrics (every one but the `episode/` averages, which are NaN in a chunk in which
    no episode ended) holding a NaN or infinity."""
    return [k for k in sorted(metrics) if not k.startswith("episode/") and not np.all(np.isfinite(metrics[k]))]


def _nonfinite_message(bad, metrics, step, last_saved, directory, logdir, removed) -> str:
    what = f"{bad[0]} became {np.asarray(metrics[bad[0]]).tolist()} (per seed)"
    if len(bad) > 1:
        what += f" (also non-finite: {', '.join(bad[1:])})"
    if last_saved is not None:
        kept = f"The last good checkpoint (env step {last_saved}) is kept in {directory}."
    elif removed:
        kept = f"No checkpoint had been saved yet, so none is kept; the run directory {logdir} was removed."
    else:
        kept = f"No checkpoint had been saved yet, so none is kept in {directory}."
    return f"{what} in the updates ending at env step {step}; training stopped. {kept}"


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
    export.save(os.path.join(ckpt.step_dir(step), export.DIRNAME), learner, state.learner, config_json(config), step)


def restore_state(ckpt: Checkpointer, step: int, programs: Programs, config: TrainConfig, with_envs: bool):
    """The `TrainState` saved at `step`. A checkpoint saved without env states gets fresh episodes,
    drawn from keys that depend on the seed and the step (not on the start's keys); so does one whose env
    states do not fit this code's env (another version of it wrote them), with a warning."""
    learner_only = _learner_only(programs.abstract_state, programs.learner)
    if with_envs:
        try:
            return ckpt.restore(step, programs.abstract_state)[0]
        except Exception as error:  # damage, or a state layout this code does not have
            try:
                saved = ckpt.restore_matching(step, learner_only)
            except Exception:
                raise error from None  # the learner does not read either: damage (or another learner)
            warnings.warn(f"checkpoint {ckpt.step_dir(step)}: its env states do not fit this env's "
                          f"({_first_line(error)}); resuming its learner with fresh episodes.", stacklevel=2)
    else:
        saved, _ = ckpt.restore(step, learner_only)
    fresh = programs.init(jax.vmap(jax.random.fold_in, (0, None))(seed_keys(config), step))
    transient = {name: getattr(fresh.learner, name) for name in _transient_fields(programs.learner)}
    return fresh.replace(learner=saved.learner.replace(**transient), key=saved.key, updates=saved.updates)


def learner_only_checkpoint(logdir: str, dest_logdir: str) -> int:
    """Saves the newest intact checkpoint of run `logdir` learner-only (`TrainConfig.checkpoint_envs` False: no
    env states, no replay buffer) into `dest_logdir/checkpoints/`, with its policy export; returns its env step.
    PPO's 8,192 env states make most of its checkpoint, so the copy is a small fraction of it; a checkpoint
    saved learner-only already (the fast SAC presets') is saved again unchanged. The resume from the copy starts
    fresh episodes and, off-policy, refills the buffer. Restored on one device, whatever the run used."""
    folder = os.path.join(logdir, "checkpoints")
    if not os.path.isdir(folder):
        raise ValueError(f"logdir={logdir!r} holds no checkpoints folder: allowed is the directory of a run with "
                         "at least one readable checkpoint.")
    ckpt = Checkpointer(folder)

    def prepare(step, saved):
        config = dataclasses.replace(saved, devices=1)  # a run field: restoring needs no other device
        validate_stored(config)  # an error here is not damage: it propagates
        return config, programs_for(config)

    def load(step, prepared):  # the learner by tree path: whatever env states (and env version) the run saved
        config, programs = prepared
        return ckpt.restore_matching(step, _learner_only(programs.abstract_state, programs.learner))

    try:
        step, prepared, state, bad = _newest_intact(ckpt, prepare, load)
        if step is None:
            raise ValueError(f"logdir={logdir!r} holds no intact checkpoint ({_damage_report(ckpt, bad)}): allowed "
                             "is the directory of a run with at least one readable checkpoint.")
    finally:
        ckpt.close()
    config, programs = prepared
    out = Checkpointer(os.path.join(dest_logdir, "checkpoints"), keep=1)
    try:
        save_checkpoint(out, step, state, dataclasses.replace(config, checkpoint_envs=False), programs.learner)
    finally:
        out.close()
    return step


def export_checkpoint(step_dir: str) -> str:
    """Writes the policy export of an existing checkpoint (reading its whole training state once: slow for
    SAC's replay buffer; its learner by tree path, whatever env states it holds); returns the export directory."""
    step_dir = os.path.abspath(step_dir)
    step = int(os.path.basename(step_dir))
    ckpt = Checkpointer(os.path.dirname(step_dir))
    try:
        config_dict = ckpt.restore_config(step)
        config = config_from_json(config_dict)
        validate_stored(config)
        programs = programs_for(config)
        state = ckpt.restore_matching(step, _learner_only(programs.abstract_state, programs.learner))
    finally:
        ckpt.close()
    return export.save(os.path.join(step_dir, export.DIRNAME), programs.learner, state.learner, config_dict, step)


def evaluate(programs: Programs, state, config: TrainConfig) -> dict:
    """Deterministic-policy metrics per seed, {name: [value per seed]}."""
    out = programs.evaluate(state.learner, jax.random.PRNGKey(config.eval_seed))
    return {k: np.asarray(v).tolist() for k, v in jax.device_get(out).items()}


STOP_SIGNALS = (signal.SIGINT, signal.SIGUSR2)
"""Signals that ask a run to save a checkpoint after the current chunk and return "interrupted": Ctrl-C, and
SIGUSR2, the scheduler's warning before a time limit or a preemption (Slurm's `--signal`, submitit's default)."""


def succeeded(config: TrainConfig, metrics: dict | None) -> bool:
    """Whether `stop_at_success` is set and every seed's training episodes of the last chunk reached it."""
    reached = (metrics or {}).get("episode/target_reached")
    return bool(config.stop_at_success) and reached is not None and bool(np.all(np.asarray(reached) >= config.stop_at_success))


def _install_sigint(flag: dict):
    """Installs the stop handler for `STOP_SIGNALS` (a second Ctrl-C aborts without saving); returns the handlers it
    replaced, None off the main thread."""
    def handler(signum, frame):
        if flag["flag"] and signum == signal.SIGINT:
            raise KeyboardInterrupt
        flag["flag"] = True
        what = "Ctrl-C" if signum == signal.SIGINT else signal.Signals(signum).name
        print(f"\n{what}: saving a checkpoint after the current chunk (press Ctrl-C again to abort without saving).",
              file=sys.stderr, flush=True)

    try:
        return {sig: signal.signal(sig, handler) for sig in STOP_SIGNALS}
    except ValueError:  # not the main thread
        return None


def _restore_sigint(previous) -> None:
    for sig, handler in (previous or {}).items():
        if handler is not None:
            signal.signal(sig, handler)
