"""Shared test setup: float32 JAX with a persistent compilation cache (git-ignored .jax_cache/, or
$JAX_COMPILATION_CACHE_DIR where set: an empty folder measures the tests' cold cost)."""

import os

import jax
import pytest

from eval_runs import ARM_ENV, point_mass_run, untrained_export

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
CACHE = os.environ.get("JAX_COMPILATION_CACHE_DIR", os.path.join(ROOT, ".jax_cache"))

jax.config.update("jax_enable_x64", False)
jax.config.update("jax_compilation_cache_dir", CACHE)
jax.config.update("jax_persistent_cache_min_compile_time_secs", 1.0)


@pytest.fixture(scope="module")
def point_run(tmp_path_factory):
    """A 2-seed point-mass PPO run with checkpoints at 5120 and 10240 env steps (eval_runs.py), once per module."""
    return point_mass_run(tmp_path_factory.mktemp("point"))


@pytest.fixture(scope="module")
def arm_export(tmp_path_factory):
    """An untrained UR5e reach policy's export (eval_runs.py), once per module."""
    return untrained_export(tmp_path_factory.mktemp("arm"), **ARM_ENV)
