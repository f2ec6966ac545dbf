"""Traced evaluation programs kept on disk, so that a later process evaluating the same setting skips tracing and
lowering it (eval.py turns this on beside JAX's persistent compilation cache).

JAX's persistent cache keeps compiled executables keyed by the lowered program, so every process still traces and
lowers its program to find its executable (results/time_to_result). This keeps the lowered program itself
(`jax.export`'s serialization: a flatbuffer of StableHLO, no pickling), behind a checksum, under a key of what shapes
it: the caller's description of the program (env and algorithm configs, sizes), the arguments' shapes and dtypes,
the backend and device kind, the versions of the packages traced into it, JAX's tracing options, and a digest of
every file of the `envs` and `agents` packages and the robot models, taken when the store is turned on. Programs are
kept in a folder per digest; turning the store on deletes the other digests' folders, so edited code leaves no
programs behind. A program with a host callback (the CPU's native MuJoCo backend) cannot be exported: it is marked
so and runs as a plain jitted function.

Only for programs built from the package's own code: an env or learner defined in a notebook, or a function of the
package replaced at run time, is not in the digest, which is why the library leaves the store off and only eval.py's
command line turns it on (`use`). Its folder runs what it holds, like JAX's cache: trust it as that one.
"""

from __future__ import annotations

import hashlib
import importlib.metadata
import importlib.util
import os
import pathlib
import shutil
import threading
import warnings
from typing import Callable

import jax

import envs
from agents.checkpoint import write_atomic
from envs.robots.base import ASSETS

SOURCES = (pathlib.Path(envs.__file__).parent, pathlib.Path(__file__).resolve().parent, ASSETS)
"""Folders whose files shape a traced program: the two packages and the robot models."""
PACKAGES = ("jax", "jaxlib", "mujoco", "mujoco-mjx", "flax", "numpy", "distrax", "tfp-nightly",
            "tensorflow-probability", "optax", "chex", "flatbuffers")
"""Installed packages whose code is traced into a program or writes it (their versions are part of the key)."""
TRACING_OPTIONS = ("jax_enable_x64", "jax_default_matmul_precision", "jax_default_prng_impl",
                   "jax_threefry_partitionable", "jax_numpy_dtype_promotion", "jax_enable_custom_prng",
                   "jax_use_shardy_partitioner", "jax_export_calling_convention_version")
"""JAX options that change what tracing or exporting produces."""
UNEXPORTABLE = b"unexportable\n"
"""The content of a program's file when it cannot be exported (a host callback): it is traced in every process."""
CHECKSUM_BYTES = 32
"""A stored program starts with the sha256 of the rest: a damaged file is traced again rather than run."""

_folder: str | None = None
_digest: str | None = None
_lock = threading.Lock()  # one export per program when threads evaluate


def use(folder: str | None) -> None:
    """Keeps programs under `folder` from now on (None: off, the default). Takes the source digest now, so code
    edited after this call cannot be stored under it, and deletes the folders of other digests."""
    global _folder, _digest
    if folder is None:
        _folder = _digest = None
        return
    if importlib.util.find_spec("flatbuffers") is None:  # jax.export's serialization needs it
        warnings.warn("traced programs are not kept: flatbuffers is not installed (pip install -e . installs it)")
        _folder = _digest = None
        return
    _digest = source_digest()
    _folder = os.path.join(folder, _digest[:16])
    if os.path.isdir(folder):
        for name in os.listdir(folder):
            if name != _digest[:16] and len(name) == 16 and os.path.isdir(os.path.join(folder, name)):
                shutil.rmtree(os.path.join(folder, name), ignore_errors=True)


def source_digest() -> str:
    """sha256 over the relative path and bytes of every file in `SOURCES` (compiled bytecode excepted)."""
    digest = hashlib.sha256()
    for top in SOURCES:
        for path in sorted(top.rglob("*")):
            if path.is_file() and "__pycache__" not in path.parts:
                digest.update(f"{top.name}/{path.relative_to(top)}".encode() + b"\0" + path.read_bytes() + b"\0")
    return digest.hexdigest()


def _versions() -> tuple:
    found = []
    for name in PACKAGES:
        try:
            found.append((name, importlib.metadata.version(name)))
        except importlib.metadata.PackageNotFoundError:
            found.append((name, None))
    return tuple(found)


def key(description: tuple, args, digest: str | None = None) -> str:
    """The file name a program of `description` called with `args` is kept under (weak types are left out: a stored
    program's outputs are strongly typed, which `device_get` makes no difference to)."""
    signature = [(tuple(x.shape), str(x.dtype)) for x in jax.tree.leaves(args)]
    parts = (description, str(jax.tree.structure(args)), signature, jax.default_backend(), jax.devices()[0].device_kind,
             _versions(), tuple((name, str(getattr(jax.config, name, None))) for name in TRACING_OPTIONS),
             digest or _digest or source_digest())
    return hashlib.sha256(repr(parts).encode()).hexdigest()


class Stored:
    """`fn(*args)` (a jitted function of arrays) through the store when it is on: the program loaded from the store,
    or exported into it on first use; a plain call of `fn` when the store is off or the program cannot be exported.
    `description`: what, besides the arguments' shapes, determines the traced program (repr-able values)."""

    def __init__(self, fn: Callable, description: tuple):
        self.fn = fn
        self.description = description
        self.calls: dict = {}
        """Argument signature -> the callable of flat arguments that runs it."""
        self.loaded = 0
        """Programs read from the store rather than traced (what tests/test_program_store.py counts)."""

    def __call__(self, *args):
        if _folder is None:
            return self.fn(*args)
        leaves, treedef = jax.tree.flatten(args)  # exported programs take a flat list: custom nodes need no codec
        signature = (str(treedef), tuple((tuple(x.shape), str(x.dtype)) for x in leaves))
        with _lock:
            call = self.calls.get(signature)
            if call is None:
                call = self.calls[signature] = self._program(leaves, treedef, _folder)
        return call(leaves)

    def _program(self, leaves: list, treedef, folder: str) -> Callable:
        path = os.path.join(folder, key(self.description, jax.tree.unflatten(treedef, leaves)) + ".bin")
        flat = jax.jit(lambda flat: self.fn(*jax.tree.unflatten(treedef, flat)))
        blob = _read(path)
        if blob == UNEXPORTABLE:
            return flat
        if blob is not None:
            self.loaded += 1
            return jax.jit(jax.export.deserialize(bytearray(blob)).call)
        try:
            exported = jax.export.export(flat)(leaves)
        except NotImplementedError as error:  # host callbacks have no serialized form
            warnings.warn(f"the evaluation program is traced in every process: {error}")
            _write(path, UNEXPORTABLE)
            return flat
        payload = bytes(exported.serialize())
        _write(path, hashlib.sha256(payload).digest() + payload)
        return jax.jit(exported.call)


def _read(path: str) -> bytes | None:
    """The stored program's serialization or `UNEXPORTABLE`; None when absent or damaged (with a warning)."""
    try:
        with open(path, "rb") as f:
            blob = f.read()
    except FileNotFoundError:
        return None
    if blob == UNEXPORTABLE:
        return blob
    payload = blob[CHECKSUM_BYTES:]
    if hashlib.sha256(payload).digest() != blob[:CHECKSUM_BYTES]:
        warnings.warn(f"stored program {path} is damaged (checksum mismatch): tracing it again")
        return None
    return payload


def _write(path: str, blob: bytes) -> None:
    """`blob` to `path` atomically (processes may share the store); a folder that cannot be written is warned
    about, and the evaluation goes on."""
    try:
        os.makedirs(os.path.dirname(path), exist_ok=True)
        write_atomic(path, blob)
    except OSError as error:
        warnings.warn(f"the evaluation program could not be kept in {path}: {error}")
