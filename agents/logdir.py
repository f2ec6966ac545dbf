"""A run's directory: what a run writes there, the checks before anything is written, and an earlier run
that `overwrite` replaces, set aside until the new run has a checkpoint (so a new run that fails to build
or to start leaves the earlier one where it was)."""

from __future__ import annotations

import dataclasses
import datetime
import os
import shutil
import tempfile

RUN_FILES = ("checkpoints", "corrupt_checkpoints", "config.json", "metrics.csv", "eval.json", "tb", "wandb")
"""What a run writes into its logdir (`overwrite` replaces these, and only these)."""
ASIDE_PREFIX = ".replaced-run-"
"""Folder inside the logdir that holds an earlier run's files while the run replacing it has no checkpoint."""


@dataclasses.dataclass
class Prepared:
    created: bool
    """This call created the logdir (a failure before the first checkpoint removes it again)."""
    aside: str | None = None
    """Where the earlier run's files wait (overwrite) until `discard_aside`, or `restore_aside` puts them back."""


def prepare(logdir: str, resume: bool, overwrite: bool) -> Prepared:
    """Checks `logdir` before anything is written and makes it ready. ValueError (naming the directory) for a
    file in the way, a directory that cannot be created or written, an earlier run without `resume` or
    `overwrite`, or `resume` without a checkpoint (then nothing is created). With `overwrite`, the earlier
    run's `RUN_FILES` move into an aside folder."""
    if os.path.exists(logdir) and not os.path.isdir(logdir):
        raise ValueError(f"logdir={logdir!r} is a file: allowed is a directory (a new one, or an earlier run's with "
                         "resume=True, --resume on the command line).")
    if resume:
        if not os.path.isdir(os.path.join(logdir, "checkpoints")):
            raise ValueError(f"resume=True but logdir={logdir!r} holds no checkpoint: allowed is the directory of an "
                             "earlier run.")
        check_writable(logdir)
        return Prepared(created=False)
    earlier = [name for name in RUN_FILES if os.path.exists(os.path.join(logdir, name))
               and not (os.path.isdir(os.path.join(logdir, name)) and not os.listdir(os.path.join(logdir, name)))]
    if earlier and not overwrite:
        raise ValueError(f"logdir={logdir!r} holds an earlier run ({', '.join(earlier)}): allowed are resume=True "
                         "(--resume) to continue it, a new logdir (--logdir), or overwrite=True (--overwrite) to "
                         "replace the earlier run once the new one has saved its first checkpoint.")
    created = not os.path.exists(logdir)
    try:
        os.makedirs(logdir, exist_ok=True)
    except OSError as error:
        raise ValueError(f"logdir={logdir!r} cannot be created ({error.strerror or error}): allowed is a directory "
                         "you can write to.") from None
    check_writable(logdir)
    return Prepared(created, set_aside(logdir) if earlier else None)


def check_writable(logdir: str) -> None:
    # A real write: os.access says yes to root even on file systems that refuse writes.
    try:
        with tempfile.TemporaryFile(dir=logdir):
            pass
    except OSError as error:
        raise ValueError(f"logdir={logdir!r} is not writable ({error.strerror or error}): allowed is a directory you "
                         "can write to.") from None


def remove_run_files(logdir: str, remove_dir: bool = False) -> None:
    """Removes what a run wrote into `logdir` (`RUN_FILES`); with `remove_dir`, also `logdir` itself
    if nothing else is left in it."""
    for name in RUN_FILES:
        path = os.path.join(logdir, name)
        if os.path.isdir(path) and not os.path.islink(path):
            shutil.rmtree(path)
        elif os.path.lexists(path):
            os.remove(path)
    if remove_dir and os.path.isdir(logdir) and not os.listdir(logdir):
        os.rmdir(logdir)


def set_aside(logdir: str) -> str:
    """Moves the run files of `logdir` into a new aside folder inside it (a rename: nothing is copied)."""
    aside = os.path.join(logdir, ASIDE_PREFIX + datetime.datetime.now().strftime("%Y%m%d-%H%M%S-%f"))
    os.makedirs(aside)
    for name in RUN_FILES:
        if os.path.lexists(os.path.join(logdir, name)):
            os.replace(os.path.join(logdir, name), os.path.join(aside, name))
    return aside


def restore_aside(logdir: str, aside: str) -> None:
    """Removes the new run's files and moves the earlier run's back from `aside`."""
    remove_run_files(logdir)
    for name in os.listdir(aside):
        os.replace(os.path.join(aside, name), os.path.join(logdir, name))
    os.rmdir(aside)


def discard_aside(aside: str) -> None:
    """Deletes the earlier run's files: the run replacing them has saved a checkpoint."""
    shutil.rmtree(aside)
