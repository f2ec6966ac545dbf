"""A fresh run compiles its training chunk in a thread while `init` compiles and runs (`Programs.chunk_ahead`): the
executable compiled from `init`'s output shapes is the one the first chunk call runs, and the wait left for it counts
in the first chunk's logged time."""

import csv
import threading
import time

import jax
import jax.numpy as jnp
import pytest

from agents import driver, loop, presets
from agents.ahead import Ahead
from agents.config import num_devices, total_updates
from agents.ppo import PPO

RUN = dict(num_timesteps=10_240, seeds=2, eval_envs=0, log_every=5_120, tensorboard=False, progress=False)
"""Two chunks of the point-mass PPO preset, two seeds."""


def test_the_chunk_compiled_ahead_is_the_one_the_first_call_runs(caplog):
    """Fresh programs (not the in-memory ones other tests compiled): after `chunk_ahead(keys)` and `init(keys)` the
    call compiles nothing, so the shapes, types and placements `init.eval_shape` gave are those `init` returned."""
    config = presets.make_config("point-mass-ppo", **RUN)
    programs = driver.build_programs.__wrapped__(config.env_name, config.env, config.algo, config.seeds,
                                                 num_devices(config), total_updates(config), config.eval_envs,
                                                 config.eval_last_steps, PPO, config.multi_device)
    assert programs is not driver.programs_for(config)
    keys = driver.seed_keys(config)
    jax.config.update("jax_log_compiles", True)  # for every thread (the context manager's setting is the caller's)
    try:
        with caplog.at_level("WARNING"):
            ahead = programs.chunk_ahead(keys)
            state = programs.init(keys)
            ahead.join()
            compiled_ahead = [r.getMessage() for r in caplog.records if "compilation of jit(chunk)" in r.getMessage()]
            caplog.clear()
            jax.block_until_ready(programs.chunk(state, jnp.int32(1)))
            at_call = [r.getMessage() for r in caplog.records if "compilation of jit(chunk)" in r.getMessage()]
    finally:
        jax.config.update("jax_log_compiles", False)
    assert compiled_ahead  # jax logs "Finished XLA compilation of jit(chunk)" where it compiles or loads it
    assert at_call == []


def ahead_threads() -> list:
    return [t for t in threading.enumerate() if t.name.startswith("ahead: ")]


def test_a_fresh_run_waits_for_its_chunk_in_the_first_chunks_time(tmp_path, monkeypatch):
    """A chunk compile standing in as a 3 s sleep, the programs already compiled in memory by a first run: the
    second run's first chunk logs the wait (its own run takes milliseconds), and no compiling thread outlives it."""
    first = presets.make_config("point-mass-ppo", logdir=str(tmp_path / "first"), **RUN)
    driver.train(first)
    monkeypatch.setattr(loop.Programs, "chunk_ahead", lambda self, keys: Ahead(lambda: time.sleep(3.0), "the chunk"))
    driver.train(presets.make_config("point-mass-ppo", logdir=str(tmp_path / "second"), **RUN))
    with open(tmp_path / "second" / "metrics.csv") as f:
        seconds = [float(row["wall_seconds"]) for row in csv.DictReader(f) if row["seed"] == "0"]
    assert seconds[0] > 2.0
    assert seconds[1] < 2.0  # the control: a chunk of its own takes far less
    assert ahead_threads() == []


def test_a_run_that_fails_before_training_leaves_no_thread_and_no_logdir(tmp_path, monkeypatch):
    """A failure after init (writing config.json here): the new logdir is removed and the chunk's compile (a 2 s
    sleep) is waited for before the error propagates."""
    monkeypatch.setattr(loop.Programs, "chunk_ahead", lambda self, keys: Ahead(lambda: time.sleep(2.0), "the chunk"))
    monkeypatch.setattr(driver, "write_atomic", lambda *args: (_ for _ in ()).throw(OSError("disk full")))
    with pytest.raises(OSError, match="disk full"):
        driver.train(presets.make_config("point-mass-ppo", logdir=str(tmp_path / "run"), **RUN))
    assert ahead_threads() == []
    assert not (tmp_path / "run").exists()


@pytest.mark.parametrize("options", [dict(stop_after_seconds=600.0, num_timesteps=15_360),
                                     dict(matmul_precision="highest", num_timesteps=20_480)])
def test_the_run_compiles_its_chunk_once(options, tmp_path, caplog):
    """With a time limit (the driver then compiles the chunk ahead as well) or a matmul precision (a context of the
    run's thread, which the compiling thread takes over): one compilation of the chunk, the thread's. Settings of
    their own (3 seeds, a length no other test trains), so that no other test compiled their programs in this
    process (the precision is not part of the programs' cache key)."""
    config = presets.make_config("point-mass-ppo", logdir=str(tmp_path / "run"), **{**RUN, "seeds": 3, **options})
    jax.config.update("jax_log_compiles", True)
    try:
        with caplog.at_level("WARNING"):
            driver.train(config)
    finally:
        jax.config.update("jax_log_compiles", False)
    assert len([r for r in caplog.records if "compilation of jit(chunk)" in r.getMessage()]) == 1
