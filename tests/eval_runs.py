"""Runs and policy exports that several test files of eval.py evaluate, and eval.py run as a command: plain
functions, which conftest.py's module-scoped fixtures `point_run` and `arm_export` call once per test file."""

import os
import subprocess
import sys

import jax

import envs
from agents import driver, export, presets, registry
from agents.config import config_json
from limits import HANG_GUARD_S

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
QUIET = dict(tensorboard=False, progress=False)
ARM_ENV = dict(substeps=2, episode_length=20)
"""The untrained arm export's env settings: few substeps and short episodes, for the CPU."""


def eval_process(*args, timeout=HANG_GUARD_S) -> subprocess.CompletedProcess:
    """`python eval.py ARGS` in a subprocess sharing the tests' compilation cache (conftest.py)."""
    path = os.pathsep.join(p for p in (ROOT, os.environ.get("PYTHONPATH", "")) if p)
    env = dict(os.environ, PYTHONPATH=path, JAX_COMPILATION_CACHE_DIR=jax.config.jax_compilation_cache_dir,
               JAX_PERSISTENT_CACHE_MIN_COMPILE_TIME_SECS="1")
    return subprocess.run([sys.executable, "eval.py", *args], cwd=ROOT, env=env, capture_output=True, text=True,
                          timeout=timeout)


def point_mass_run(directory):
    """A 2-seed point-mass PPO run under `directory`/run with checkpoints at 5120 and 10240 env steps (compiles in
    seconds); returns its logdir."""
    logdir = directory / "run"
    config = presets.make_config("point-mass-ppo", num_timesteps=10240, checkpoint_every=5120, seeds=2,
                                 eval_envs=64, logdir=str(logdir), **QUIET)
    driver.train(config)
    return logdir


def untrained_export(directory, env_name="ur5e-reach", **env_options):
    """A policy export as the driver writes it, of an untrained PPO policy (no compilation: evaluation needs only its
    shapes and config; training it would compile PPO for a minute); returns its logdir."""
    config = presets.make_config("ur5e-reach-ppo-cpu", env_name=env_name, env=envs.make_config(env_name, **env_options))
    env = envs.make(env_name, **env_options)
    learner = registry.make_learner(config.algo, env.observation_size, env.action_size, 1)
    state = jax.vmap(learner.init)(jax.random.split(jax.random.PRNGKey(0), 1))
    step_dir = directory / "run" / "checkpoints" / "1280"
    export.save(str(step_dir / "policy"), learner, state, config_json(config), 1280)
    return step_dir.parent.parent
