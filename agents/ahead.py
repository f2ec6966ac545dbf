"""Compiling a training run's programs before they are called: `Ahead` in a thread while the device (or the main
thread) works on something else, `compile_ahead` at once."""

from __future__ import annotations

import sys
import threading
import time
import warnings

import jax
import jax.numpy as jnp


class Ahead:
    """`fn()` run at once in a thread of its own, for compiling a program on the host while the device works (XLA's
    compiler releases Python's GIL; tracing and lowering hold it). `join()` waits for it; an error it raised becomes a
    warning, since the program is then compiled again where it is called, which reports the error if it persists."""

    def __init__(self, fn, what: str):
        self.error, self.what = None, what

        def run():
            try:
                fn()
            except Exception as error:  # compiled again on use
                self.error = error

        self.thread = threading.Thread(target=run, name=f"ahead: {what}")
        self.thread.start()

    def join(self) -> None:
        self.thread.join()
        if self.error is not None:
            warnings.warn(f"compiling {self.what} ahead failed ({self.error!r}); it is compiled on use", stacklevel=2)
            self.error = None


def compiling(program, *args, what: str) -> Ahead:
    """`program.lower(*args).compile()` in a thread, at the caller's matmul precision (a context of the caller's
    thread, which the compiling thread enters: else the call would compile again at the caller's)."""
    precision = jax.config.jax_default_matmul_precision

    def compile_it():
        with jax.default_matmul_precision(precision):
            program.lower(*args).compile()

    return Ahead(compile_it, what)


def finish(*aheads: Ahead | None) -> None:
    """Waits, saying so, for each of `aheads` still compiling, when a run ends before it needed them: no compiling
    thread outlives the run. Their errors do not matter then."""
    for ahead in aheads:
        if ahead is not None and ahead.thread.is_alive():
            print(f"waiting for {ahead.what}'s compile to end ...", file=sys.stderr, flush=True)
            ahead.thread.join()


def compile_ahead(programs, state) -> float:
    """Compiles `programs.chunk` (`agents.loop.Programs`) for `state` without running it (the jit call then reuses the
    executable); returns the seconds it took (few after `Programs.chunk_ahead`, or with a persistent compilation
    cache)."""
    t0 = time.perf_counter()
    programs.chunk.lower(state, jnp.int32(1)).compile()
    return time.perf_counter() - t0
