"""Traced evaluation programs kept on disk, so that a later process evaluating the same setting skips tracing and
lowering it (eval.py turns this on beside JAX's persistent compilation cache).

JAX's persistent cache keeps compiled executables keyed by the lowered program, so every process still traces and
lowers its program to find its executable: for an arm's evaluation 2-3 s of a few seconds' work
(results/time_to_result). This keeps the lowered program itself (`jax.export`'s serialization: a flatbuffer of
StableHLO, no pickling) under a key of everything that shapes it: the caller's description of the program (env and
algorithm configs, sizes), the arguments' shapes, the platform, the versions of JAX, MuJoCo and the other packages
traced into it, JAX's tracing options, and a digest of every file of `envs/`, `agents/` and `assets/` (an edited
source file or robot model is a new key). A program that cannot be exported (a host callback of the CPU's native
MuJoCo backend) is marked so and runs as a plain jitted function.

Only for programs built from the package's own code: an env or learner defined in a notebook, or a function of the
package replaced at run time, is not in the digest, which is why the library leaves this off and only eval.py's
command line turns it on (`use`).
"""

from __future__ import annotations

import functools
import hashlib
import importlib.metadata
import os
import pathlib
import warnings
from typing import Callable

import jax

ROOT = pathlib.Path(__file__).resolve().parents[1]
SOURCES = ("envs", "agents", "assets")
"""Folders under the checkout whose files shape a traced program."""
PACKAGES = ("jax", "jaxlib", "mujoco", "mujoco-mjx", "flax", "numpy")
"""Installed packages whose code is traced into a program (their versions are part of the key)."""
TRACING_OPTIONS = ("jax_enable_x64", "jax_default_matmul_precision", "jax_default_prng_impl",
                   "jax_threefry_partitionable")
"""JAX options that change what tracing produces."""
UNEXPORTABLE = b"unexportable\n"

_folder: str | None = None


def use(folder: str | None) -> None:
    """Keeps programs in `folder` (created when first written) from now on; None: off (the default)."""
    global _folder
    _folder = folder


@functools.lru_cache(maxsize=1)
def source_digest() -> str:
    """sha256 over the path and bytes of every file in `SOURCES` (compiled bytecode excepted)."""
    digest = hashlib.sha256()
    for top in SOURCES:
        for path in sorted((ROOT / top).rglob("*")):
            if path.is_file() and "__pycache__" not in path.parts:
                digest.update(str(path.relative_to(ROOT)).encode() + b"\0" + path.read_bytes() + b"\0")
    return digest.hexdigest()


def _versions() -> tuple:
    found = []
    for name in PACKAGES:
        try:
            found.append((name, importlib.metadata.version(name)))
        except importlib.metadata.PackageNotFoundError:
            found.append((name, None))
    return tuple(found)


def key(description: tuple, args) -> str:
    """The file name a program of `description` called with `args` is kept under."""
    signature = [(tuple(x.shape), str(x.dtype)) for x in jax.tree.leaves(args)]
    device = jax.devices()[0]
    parts = (description, str(jax.tree.structure(args)), signature, device.platform, device.device_kind,
             _versions(), tuple((name, str(getattr(jax.config, name))) for name in TRACING_OPTIONS), source_digest())
    return hashlib.sha256(repr(parts).encode()).hexdigest()


class Stored:
    """`fn(*args)` (a jitted function of arrays) through the store when it is on: the program loaded from the store,
    or exported into it on first use; a plain call of `fn` when the store is off or the program cannot be exported.
    `description`: what, besides the arguments' shapes, determines the traced program (repr-able values)."""

    def __init__(self, fn: Callable, description: tuple):
        self.fn = fn
        self.description = description
        self._calls: dict = {}
        self.loaded = 0
        """Programs read from the store rather than traced (tests and benchmarks count them)."""

    def __call__(self, *args):
        if _folder is None:
            return self.fn(*args)
        leaves, treedef = jax.tree.flatten(args)  # exported programs take a flat list: custom nodes need no codec
        signature = (str(treedef), tuple((tuple(x.shape), str(x.dtype)) for x in leaves))
        call = self._calls.get(signature)
        if call is None:
            call = self._calls[signature] = self._program(leaves, treedef)
        return call(leaves)

    def _program(self, leaves: list, treedef) -> Callable:
        path = os.path.join(_folder, key(self.description, jax.tree.unflatten(treedef, leaves)) + ".bin")
        if os.path.exists(path):
            with open(path, "rb") as f:
                blob = f.read()
            if blob == UNEXPORTABLE:
                return lambda flat: self.fn(*jax.tree.unflatten(treedef, flat))
            try:
                exported = jax.export.deserialize(bytearray(blob))
                self.loaded += 1
                return jax.jit(exported.call)
            except Exception as error:  # a damaged file: export it again
                warnings.warn(f"program {path} could not be read ({type(error).__name__}: {error}); tracing it again")
        flat = jax.jit(lambda flat: self.fn(*jax.tree.unflatten(treedef, flat)))
        try:
            exported = jax.export.export(flat)(leaves)
            blob = bytes(exported.serialize())
        except Exception:  # host callbacks (the native backend) or custom calls without a stable format
            _write(path, UNEXPORTABLE)
            return flat
        _write(path, blob)
        return jax.jit(exported.call)


def _write(path: str, blob: bytes) -> None:
    """`blob` to `path` through a temporary file and a rename (processes may share the store)."""
    os.makedirs(os.path.dirname(path), exist_ok=True)
    tmp = f"{path}.tmp-{os.getpid()}"
    with open(tmp, "wb") as f:
        f.write(blob)
    os.replace(tmp, path)
