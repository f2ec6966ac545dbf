"""Orbax checkpoints of the full training state plus the run's config as JSON.

Layout under `<logdir>/checkpoints/<env_steps>/`: `state/` (the whole seed-batched `TrainState`:
parameters, optimiser and normaliser state, loop and env RNG, env states, update count and, for
SAC, the replay buffer, so a resumed run continues bit-for-bit), `config/` (the config JSON),
`policy/` (the small policy export that eval.py loads, written by the driver: `agents.export`) and,
for the final checkpoint, `eval.json` (evaluation metrics). Saves are synchronous: the compiled
chunk donates its input state, so the arrays must be written before the next chunk runs.
"""

from __future__ import annotations

import asyncio
import contextlib
import functools
import gc
import os
import re

import jax
import jax.numpy as jnp


def _ocp():
    """Orbax's checkpoint API, imported when a checkpoint is first written or read: evaluating a policy export never
    needs it."""
    import orbax.checkpoint as ocp

    return ocp


def _leaf_name(index: int, path) -> str:
    return f"{index:05d}{re.sub(r'[^A-Za-z0-9]+', '_', jax.tree_util.keystr(path))}"


def _rebuild(abstract_state, value_of):
    """`abstract_state`'s tree with each leaf `value_of(name, abstract leaf)` (name: `_leaf_name`), and each
    zero-size leaf, which checkpoints leave out, as zeros."""
    leaves, treedef = jax.tree_util.tree_flatten_with_path(abstract_state)
    return jax.tree_util.tree_unflatten(treedef, [
        value_of(_leaf_name(i, path), a) if a.size else jnp.zeros(a.shape, a.dtype, device=getattr(a, "sharding", None))
        for i, (path, a) in enumerate(leaves)])


def _nonempty_leaves(tree) -> dict:
    """{name: leaf} of the leaves with at least one element, named by position and tree path.

    Orbax refuses zero-size arrays, and `mjx.Data` has several (e.g. `act` of a model without
    actuator state); they carry no information and are rebuilt from the abstract state on restore.
    """
    out = {}
    for i, (path, leaf) in enumerate(jax.tree_util.tree_flatten_with_path(tree)[0]):
        if leaf.size:
            out[_leaf_name(i, path)] = leaf
    return out


def write_atomic(path: str, text: str | bytes) -> None:
    """Writes `text` (or bytes) to `path` through a temporary file and a rename: a reader (another worker of
    `tools.experiments run --parallel` reading the run's parts) sees the old file or the whole new one; a failed
    write leaves no temporary file."""
    tmp = f"{path}.tmp-{os.getpid()}"
    try:
        with open(tmp, "wb" if isinstance(text, bytes) else "w") as f:
            f.write(text)
        os.replace(tmp, path)
    finally:
        if os.path.exists(tmp):
            os.unlink(tmp)


@functools.cache
def _orbax_dir() -> str:
    """The folder of the orbax package, with a trailing separator."""
    return os.path.dirname(os.path.dirname(_ocp().__file__)) + os.sep


def _orbax_task(future: asyncio.Future) -> bool:
    """Whether `future` is a task running one of orbax's coroutines."""
    code = getattr(future.get_coro(), "cr_code", None) if isinstance(future, asyncio.Task) else None
    return code is not None and code.co_filename.startswith(_orbax_dir())


def _close_abandoned_reads() -> None:
    """Closes, quietly, the reads a failed orbax restore left pending. When one array fails to read (a damaged file),
    orbax closes its event loop with the other reads' tasks pending and the gather's error unretrieved; each would
    print at some later garbage collection ("Exception ignored in <coroutine ...>", "Task was destroyed but it is
    pending", "exception was never retrieved"), after the restore has reported the error."""
    for future in [obj for obj in gc.get_objects() if isinstance(obj, asyncio.Future) and obj.get_loop().is_closed()]:
        if not future.done() and _orbax_task(future) and future.get_coro().cr_frame is not None:
            future._log_destroy_pending = False  # asyncio's switch for that line (it has no public one)
            with contextlib.suppress(Exception):  # orbax's read turns the close into its read error, already reported
                future.get_coro().close()
        elif future.done() and not future.cancelled() and (
                _orbax_task(future) or any(_orbax_task(c) for c in getattr(future, "_children", ()))):  # a gather's
            future.exception()  # marks it retrieved


class Checkpointer:
    """Saves and restores `TrainState`s under `<directory>`, keeping the newest `keep`."""

    def __init__(self, directory: str, keep: int = 3):
        self.directory = os.path.abspath(directory)
        ocp = _ocp()
        options = ocp.CheckpointManagerOptions(max_to_keep=keep, create=True, enable_async_checkpointing=False)
        self.manager = ocp.CheckpointManager(self.directory, options=options, item_names=("state", "config"))
        self.args = ocp.args
        """Orbax's save and restore arguments."""

    def latest_step(self) -> int | None:
        return self.manager.latest_step()

    def save(self, step: int, state, config_dict: dict) -> None:
        self.manager.save(
            step, args=self.args.Composite(state=self.args.StandardSave(_nonempty_leaves(state)),
                                           config=self.args.JsonSave(config_dict)),
            force=True,
        )
        self.manager.wait_until_finished()

    def _read(self, step: int, **items):
        """Orbax's restore of `items` at `step`; a failure propagates after `_close_abandoned_reads`."""
        try:
            return self.manager.restore(step, args=self.args.Composite(**items))
        except Exception:
            with contextlib.suppress(Exception):  # the cleanup must not replace the restore's error
                _close_abandoned_reads()
            raise

    def restore(self, step: int, abstract_state):
        """The state saved at `step`, placed with the shardings of `abstract_state`."""
        restored = self._read(step, state=self.args.StandardRestore(_nonempty_leaves(abstract_state)),
                              config=self.args.JsonRestore())
        return _rebuild(abstract_state, lambda name, _: restored.state[name]), restored.config

    def restore_matching(self, step: int, abstract_state):
        """The leaves of `abstract_state` read from the state saved at `step` by their tree path, whatever else it
        holds and in whichever order: a learner out of a checkpoint whose env state another env version wrote.
        ValueError naming a leaf the checkpoint lacks or holds with another shape or dtype."""
        saved = self._read(step, state=self.args.StandardRestore()).state
        by_path = {name[5:]: value for name, value in saved.items()}  # the position prefix dropped
        if len(by_path) != len(saved):
            raise ValueError(f"checkpoint {self.step_dir(step)} names two leaves alike: allowed is unique tree paths.")

        def value_of(name, a):
            value = by_path.get(name[5:])
            if value is None or value.shape != a.shape or value.dtype != a.dtype:
                found = "none" if value is None else f"{value.dtype}{list(value.shape)}"
                raise ValueError(f"checkpoint {self.step_dir(step)} has no leaf {name[5:]} of {a.dtype}{list(a.shape)} "
                                 f"(found: {found}).")
            sharding = getattr(a, "sharding", None)
            return jax.device_put(value, sharding) if sharding is not None else value

        return _rebuild(abstract_state, value_of)

    def restore_config(self, step: int) -> dict:
        return self._read(step, config=self.args.JsonRestore()).config

    def step_dir(self, step: int) -> str:
        return os.path.join(self.directory, str(step))

    def close(self) -> None:
        self.manager.close()
