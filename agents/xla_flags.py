"""XLA settings this project runs with on NVIDIA GPUs, applied when `agents` is imported.

XLA records each run of fused kernels as a CUDA graph ("command buffer"). Its default scheduling
mode inside a graph (LHS) chains the kernels one after another in program order; the CONCURRENT
mode gives the graph the program's real data dependencies, so independent kernels run side by side:
the policy and the value network's forward and backward passes in PPO's gradient steps, the twin
critics in SAC's, independent pieces of a physics substep; PPO trains about a third faster with it
(results: throughput study). The kernels and their numbers are the same; only their order changes.
A program may need more GPU memory with it.

By default XLA does not capture `while` loops (our `lax.scan`s) in those graphs, so the host launches every
iteration's graph itself; `+WHILE` puts the loops in the graphs, which saves host launches where the loop bodies
are short: fast SAC and PPO on two GPUs train faster with it, PPO on one GPU about as fast (results: throughput
study). A run's numbers need not agree bit for bit with one made without it.

`apply()` adds each flag to `XLA_FLAGS` when

- a CUDA plugin of jaxlib is installed (CPU-only installs are left alone),
- `XLA_FLAGS` does not already set the flag (yours wins), and
- `REACH_AVOID_XLA_DEFAULTS` is not "0" (set it to 0 to run with XLA's own defaults).

XLA reads `XLA_FLAGS` once, when JAX starts its first backend: import `agents` (or `train`) before
running anything on the GPU, e.g. at the top of a notebook; a warning says when it came too late.

`compilation_cache()` turns on JAX's persistent compilation cache (train.py, eval.py and the experiment runner
call it): a program compiled once is loaded by every later process that builds the same one, so a second run,
resume or evaluation of a setting starts in seconds instead of compiling again.
"""

from __future__ import annotations

import importlib.metadata
import os
import warnings

import jax  # importing starts no backend: XLA_FLAGS is read when the first one starts

GPU_FLAGS = ("--xla_gpu_command_buffer_scheduling_mode=CONCURRENT", "--xla_gpu_enable_command_buffer=+WHILE")
"""Added to XLA_FLAGS on machines with a CUDA jaxlib plugin."""
OPT_OUT = "REACH_AVOID_XLA_DEFAULTS"
CACHE_VARIABLE = "JAX_COMPILATION_CACHE_DIR"
CACHE_SIZE_VARIABLE = "JAX_COMPILATION_CACHE_MAX_SIZE"
DEFAULT_CACHE = os.path.join(os.path.dirname(os.path.dirname(os.path.abspath(__file__))), ".jax_cache")
"""The persistent compilation cache's folder when neither a path nor $JAX_COMPILATION_CACHE_DIR names one."""
CACHE_BYTES = 4 * 2**30
"""The cache's size limit unless $JAX_COMPILATION_CACHE_MAX_SIZE sets one: past it JAX deletes the least recently
used programs (its own default is no limit, a folder that grows with every setting compiled)."""


def merged_flags(current: str, flags=GPU_FLAGS) -> str:
    """`current` XLA_FLAGS plus each of `flags` whose name it does not set already."""
    words = current.split()
    names = {w.split("=", 1)[0] for w in words}
    words += [f for f in flags if f.split("=", 1)[0] not in names]
    return " ".join(words)


def cuda_plugin_installed() -> bool:
    """Whether a jaxlib CUDA plugin (jax-cuda12-plugin, jax-cuda13-plugin, ...) is installed."""
    for dist in importlib.metadata.distributions():
        name = (dist.metadata["Name"] or "").lower().replace("_", "-")
        if name.startswith("jax-cuda"):
            return True
    return False


def _backends_started() -> bool:
    try:
        from jax._src import xla_bridge
        return bool(xla_bridge.backends_are_initialized())
    except Exception:  # private API: if it moves, assume not started
        return False


def apply(environ=None, gpu: bool | None = None) -> bool:
    """Adds `GPU_FLAGS` to `environ["XLA_FLAGS"]` (default `os.environ`) under the conditions
    above; True when it changed the variable. `gpu` overrides the plugin check (tests)."""
    environ = os.environ if environ is None else environ
    if environ.get(OPT_OUT, "1") == "0":
        return False
    if not (cuda_plugin_installed() if gpu is None else gpu):
        return False
    current = environ.get("XLA_FLAGS", "")
    merged = merged_flags(current)
    if merged.split() == current.split():
        return False
    environ["XLA_FLAGS"] = merged
    if environ is os.environ and _backends_started():
        added = " ".join(merged.split()[len(current.split()):])
        warnings.warn("agents was imported after JAX started its GPU backend: XLA_FLAGS now holds "
                      f"{added}, but this process runs without them (import agents first).", stacklevel=2)
    return True


def compilation_cache(path: str | None = None, environ=None) -> str | None:
    """Turns on JAX's persistent compilation cache in `path`, at most `CACHE_BYTES`; None: $JAX_COMPILATION_CACHE_DIR
    where it is set (an empty value turns the cache off), else `DEFAULT_CACHE`; "off": no cache. Returns the folder
    used, or None."""
    environ = os.environ if environ is None else environ
    if path is None:
        path = environ.get(CACHE_VARIABLE, DEFAULT_CACHE)
    folder = None if path in ("off", "") else path
    jax.config.update("jax_compilation_cache_dir", folder)
    if CACHE_SIZE_VARIABLE not in environ:
        jax.config.update("jax_compilation_cache_max_size", CACHE_BYTES)
    return folder
