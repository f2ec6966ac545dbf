"""XLA settings this project runs with on NVIDIA GPUs, applied when `agents` is imported.

XLA records each run of fused kernels as a CUDA graph ("command buffer"). Its default scheduling
mode inside a graph (LHS) chains the kernels one after another in program order; the CONCURRENT
mode gives the graph the program's real data dependencies, so independent kernels run side by side:
the policy and the value network's forward and backward passes in PPO's gradient steps, the twin
critics in SAC's, independent pieces of a physics substep. With it, `ur5e-reach-ppo` trained at
about 890k instead of 668k env steps/s on an H200 (env only: 1.16M instead of 988k; results/archive/lab_notebook.md,
"Training throughput"). The kernels and their numbers are the same; only their order changes (three PPO
updates gave bitwise-equal parameters with and without it). A program may need more GPU memory with it.

`apply()` adds the flag to `XLA_FLAGS` when

- a CUDA plugin of jaxlib is installed (CPU-only installs are left alone),
- `XLA_FLAGS` does not already choose a scheduling mode (yours wins), and
- `REACH_AVOID_XLA_DEFAULTS` is not "0" (set it to 0 to run with XLA's own defaults).

XLA reads `XLA_FLAGS` once, when JAX starts its first backend: import `agents` (or `train`) before
running anything on the GPU, e.g. at the top of a notebook; a warning says when it came too late.
"""

from __future__ import annotations

import importlib.metadata
import os
import warnings

GPU_FLAGS = ("--xla_gpu_command_buffer_scheduling_mode=CONCURRENT",)
"""Added to XLA_FLAGS on machines with a CUDA jaxlib plugin."""
OPT_OUT = "REACH_AVOID_XLA_DEFAULTS"


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
        warnings.warn("agents was imported after JAX started its GPU backend: XLA_FLAGS now holds "
                      f"{' '.join(GPU_FLAGS)}, but this process runs without it (import agents first).", stacklevel=2)
    return True
