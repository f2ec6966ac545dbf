"""Semantics-preserving replacements for two pieces of MJX that are slow on a GPU.

A training step of the arms is host-bound on a GPU: the host launches thousands of small kernels
and CUDA graphs per env step and the device waits (`benchmarks/trace_summary.py` on a profile of
one PPO update). Two pieces of MJX cause most of the launches, and both are replaced here by code
that computes the same numbers in fewer, larger launches:

1. Cholesky factorisations and solves. MJX factorises the arm's 6x6 (UR5e) or 7x7 (Panda) mass
   matrix, the implicit integrator's matrix and the Newton solver's Hessian with
   `jax.scipy.linalg.cho_factor` / `cho_solve` in every physics substep. On a GPU those are
   library calls (cuSOLVER potrf, cuBLAS trsm) on thousands of tiny matrices: several kernels
   each, issued one by one by the host, and each splits XLA's CUDA graphs. Written out entry by
   entry (the Cholesky-Banachiewicz recurrence, unrolled over the matrix size) they become a few
   fused element-wise kernels inside the graphs.
2. The constraint solver's line search, a `lax.scan` of `opt.ls_iterations` steps (6 here) in every
   substep: on a GPU each scan iteration is one graph launch from the host for a few microseconds
   of device work. Unrolled (`lax.scan(..., unroll=True)`), it joins the substep's graph.

`fast_mjx()` is a context manager that applies both while it is open: it routes
`jax.scipy.linalg.cho_factor` / `cho_solve` to the functions below (matrices larger than
`MAX_SIZE` keep the library path) and swaps MJX's line-search loop for the unrolled one. It is on
by default on GPU backends only (on a CPU the library calls are as fast). The arm environments open
it around their own `step`, so it is active only while JAX traces that; other code tracing at the
same moment in another thread would see it too. MJX's loop is a private function
(`mujoco.mjx._src.solver._while_loop_scan`, mujoco 3.17): if a later MJX renames it, that part is
skipped and the rest still applies.
"""

from __future__ import annotations

import contextlib
import threading

import jax
import jax.numpy as jnp
import jax.scipy.linalg

try:
    from mujoco.mjx._src import solver as _mjx_solver
except ImportError:  # pragma: no cover - a different MJX layout: only the Cholesky part applies
    _mjx_solver = None

MAX_SIZE = 12
"""Largest matrix size written out (unrolled code grows with the cube of the size)."""

_library_cho_factor = jax.scipy.linalg.cho_factor
_library_cho_solve = jax.scipy.linalg.cho_solve


def cholesky_lower(a: jax.Array) -> jax.Array:
    """Lower-triangular L with L @ L.T = a for symmetric positive definite `a` of shape (..., n, n).

    Reads the lower triangle of `a` only. A matrix that is not positive definite gives NaN on the
    diagonal from that pivot on (LAPACK reports an error code instead).
    """
    n = a.shape[-1]
    rows = [[None] * n for _ in range(n)]
    for j in range(n):
        diag = a[..., j, j] - sum(rows[j][k] * rows[j][k] for k in range(j))
        rows[j][j] = jnp.sqrt(diag)
        inv = 1.0 / rows[j][j]
        for i in range(j + 1, n):
            rows[i][j] = (a[..., i, j] - sum(rows[i][k] * rows[j][k] for k in range(j))) * inv
    zero = jnp.zeros_like(a[..., 0, 0])
    return jnp.stack([jnp.stack([rows[i][j] if j <= i else zero for j in range(n)], -1) for i in range(n)], -2)


def cholesky_solve_lower(factor: jax.Array, b: jax.Array) -> jax.Array:
    """x with (L @ L.T) x = b, for L = `factor` (..., n, n) lower triangular and b (..., n) or (..., n, k)."""
    n = factor.shape[-1]
    vector = b.ndim == factor.ndim - 1
    cols = b[..., None] if vector else b
    entry = lambda i: cols[..., i, :]
    diag = [factor[..., i, i][..., None] for i in range(n)]
    low = lambda i, j: factor[..., i, j][..., None]
    y = []
    for i in range(n):  # L y = b
        y.append((entry(i) - sum(low(i, k) * y[k] for k in range(i))) / diag[i])
    x = [None] * n
    for i in reversed(range(n)):  # L.T x = y
        x[i] = (y[i] - sum(low(k, i) * x[k] for k in range(i + 1, n))) / diag[i]
    out = jnp.stack(x, -2)
    return out[..., 0] if vector else out


def cho_factor(a, lower: bool = False, overwrite_a: bool = False, check_finite: bool = True):
    """`jax.scipy.linalg.cho_factor` with the small-matrix path: returns (factor, lower), the
    factor in the requested triangle and zeros in the other (the library leaves its input there;
    `cho_solve` reads only the factor's triangle either way)."""
    a = jnp.asarray(a)
    if a.ndim < 2 or a.shape[-1] != a.shape[-2] or a.shape[-1] > MAX_SIZE:
        return _library_cho_factor(a, lower=lower, overwrite_a=overwrite_a, check_finite=check_finite)
    factor = cholesky_lower(a if lower else jnp.swapaxes(a, -1, -2))
    return (factor if lower else jnp.swapaxes(factor, -1, -2)), lower


def cho_solve(c_and_lower, b, overwrite_b: bool = False, check_finite: bool = True):
    """`jax.scipy.linalg.cho_solve` with the small-matrix path."""
    c, lower = c_and_lower
    c, b = jnp.asarray(c), jnp.asarray(b)
    if c.ndim != 2 or c.shape[-1] > MAX_SIZE or b.ndim not in (1, 2) or b.shape[0] != c.shape[-1]:
        return _library_cho_solve(c_and_lower, b, overwrite_b=overwrite_b, check_finite=check_finite)
    return cholesky_solve_lower(c if lower else c.T, b)


def unrolled_while_loop_scan(cond_fun, body_fun, init_val, max_iter):
    """MJX's bounded while loop (`solver._while_loop_scan`: at most `max_iter` steps of `body_fun`
    while `cond_fun` holds, later steps leave the value unchanged) as a fully unrolled scan."""

    def step(carry, _):
        val, go = carry
        new = jax.lax.cond(go, body_fun, lambda v: v, val)
        return (new, jnp.logical_and(go, cond_fun(new))), None

    return jax.lax.scan(step, (init_val, cond_fun(init_val)), None, length=max_iter, unroll=True)[0][0]


def _swap(module, name, value):
    """Sets module.name = value and returns the previous value (None if the module lacks it)."""
    if module is None or not hasattr(module, name):
        return None
    previous = getattr(module, name)
    setattr(module, name, value)
    return previous


def _replacements():
    """(module, attribute, replacement) of everything `fast_mjx` swaps."""
    return ((jax.scipy.linalg, "cho_factor", cho_factor), (jax.scipy.linalg, "cho_solve", cho_solve),
            (_mjx_solver, "_while_loop_scan", unrolled_while_loop_scan))


_OPEN = {"depth": 0, "saved": []}
"""How many enabled `fast_mjx()` contexts are open (in any thread) and what the first one replaced."""
_OPEN_LOCK = threading.Lock()


@contextlib.contextmanager
def fast_mjx(enabled: bool | None = None):
    """Applies this module's replacements while open (re-entrant). `enabled=None`: on when JAX's
    default backend is a GPU (on a CPU the library calls are faster). The first context opened swaps
    them in and the last one closed swaps the originals back, also when contexts of two threads
    overlap in any order (each restoring what it found would leave a later one without them)."""
    if enabled is None:
        enabled = jax.default_backend() in ("gpu", "cuda", "rocm")
    if not enabled:
        yield
        return
    with _OPEN_LOCK:
        if _OPEN["depth"] == 0:
            _OPEN["saved"] = [(module, name, _swap(module, name, new)) for module, name, new in _replacements()]
        _OPEN["depth"] += 1
    try:
        yield
    finally:
        with _OPEN_LOCK:
            _OPEN["depth"] -= 1
            if _OPEN["depth"] == 0:
                for module, name, previous in reversed(_OPEN["saved"]):
                    if previous is not None:
                        _swap(module, name, previous)
                _OPEN["saved"] = []


def active() -> bool:
    """Whether the replacements apply now (inside an enabled `fast_mjx()`): a trace made now holds them."""
    return jax.scipy.linalg.cho_factor is cho_factor
