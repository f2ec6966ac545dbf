"""Shared test setup: float32 JAX with a persistent compilation cache (git-ignored .jax_cache/, or
$JAX_COMPILATION_CACHE_DIR where set: an empty folder measures the tests' cold cost)."""

import os

import jax

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
CACHE = os.environ.get("JAX_COMPILATION_CACHE_DIR", os.path.join(ROOT, ".jax_cache"))

jax.config.update("jax_enable_x64", False)
jax.config.update("jax_compilation_cache_dir", CACHE)
jax.config.update("jax_persistent_cache_min_compile_time_secs", 1.0)
