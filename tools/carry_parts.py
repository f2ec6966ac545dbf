"""Carries the unfinished parts of `tools.experiments` runs from one machine to the next. A GPU machine lent
for half an hour goes back with its `runs/`, and a part trained half way (by a `run --time-limit` call that ended
first) is lost with it; its learner-only checkpoint lets the next machine resume it.

    python -m tools.carry_parts pack --runs-dir runs/experiments --to $OUT/carry [NAMES]  # a machine's last call
    python -m tools.carry_parts unpack --from DIR --runs-dir runs/experiments             # the next one's first

`pack` takes every part folder (`<experiment>/<run>/seeds-<first>-<last>/`; with NAMES, experiments or
experiment/run names, only theirs) that has a checkpoint and no `eval.json` (not done) and that no other command
holds the lock of (`tools.experiments.part_lock`: it is training there), the one with the most env steps first,
saves its newest intact checkpoint learner-only (`agents.driver.learner_only_checkpoint`: no env states, no replay
buffer; per seed about 3-5 MB for the PPO presets, 16 MB for the fast SAC ones) beside its `config.json` and
`metrics.csv`, and writes each part as its own gzipped tar, `<experiment>__<run>__<part>.tgz.NNN`, split into pieces
of at most `--max-mb`, in bundles of at most `--max-total-mb` (default 24: a device call brings back files of at
most 16 MiB, and the next call's working tree, which carries one bundle in a git-ignored folder beside the
repository, and beside the wheels only where it is small, is limited to 64 MiB): the first bundle in `--to`, the
parts that do not fit beside it in `--to`/more-1, more-2, ... (first fit), each for another call of the next
machine (`--to` at most one folder below the call's $OUT: a call brings back files at most two folders down, 8 of
them, 64 MiB in all, which `pack` keeps to). A part that cannot be saved, is larger than a bundle or passes those
limits is left out and named. Until its bundle is unpacked there, a part in a later bundle looks new to the next
machine: leave its run out of the calls before that one, or it starts afresh. A resume from the copy starts fresh
episodes and, for SAC, refills the replay buffer: not bit-for-bit the run that would have gone on, the same as any
learner-only resume.

`unpack` puts each complete archive's part into the runs folder, except where the folder there is done
(`eval.json`), has a checkpoint at that step or later, or holds another config; an archive with a piece missing or
damaged is named and skipped.
"""

from __future__ import annotations

import argparse
import io
import json
import os
import re
import shutil
import tarfile
import tempfile

from tools.experiments import checkpoint_steps, parse_part, part_lock, run_folders, select

PIECE = re.compile(r"(?P<archive>.+\.tgz)\.(?P<index>\d{3})")
PIECE_MB = 15.0
"""The largest piece `pack` writes, in MiB: a device call brings back files of at most 16 MiB."""
TOTAL_MB = 24.0
"""A bundle's size in MiB, what one device call carries: its working tree holds the bundle beside the repository
(~31 MiB) within 64 MiB, and beside the wheels (~20 MiB) too only where the bundle is small; 24 holds one
three-seed paper-setting SAC part (~18 MiB) or one fast-SAC part (~15.2 MiB)."""
RETURN_FILES = 7
"""The most pieces `pack` writes in all its bundles: a device call brings back at most 8 files, one kept for the
call's logs."""
RETURN_MB = 60.0
"""The most MiB `pack` writes in all its bundles: a device call brings back at most 64 MiB."""


def unfinished_parts(runs_dir: str, runs: list[str] | None = None) -> list[str]:
    """The part folders under `runs_dir` (relative, `<experiment>/<run>/seeds-F-L`) with a checkpoint and no
    eval.json, sorted by name; with `runs` (`<experiment>/<run>` folders), only theirs."""
    found = []
    for root, dirs, files in os.walk(runs_dir):
        if parse_part(os.path.basename(root)) is not None:
            dirs[:] = []
            if "eval.json" not in files and newest_step(root) is not None:
                found.append(os.path.relpath(root, runs_dir))
    if runs is not None:
        folders = {os.path.normpath(r) for r in runs}
        found = [rel for rel in found if os.path.dirname(rel) in folders]
    return sorted(found)


def newest_step(part_dir: str) -> int | None:
    """The env step of the newest checkpoint of `part_dir` (`checkpoint_steps`), None if there is none."""
    steps = checkpoint_steps(part_dir)
    return steps[-1] if steps else None


def archive_name(rel: str) -> str:
    """'sac-fast/panda-reach/seeds-0-0' -> 'sac-fast__panda-reach__seeds-0-0.tgz' (a file name a device call
    brings back: letters, digits, '.', '_' and '-')."""
    return "__".join(rel.split(os.sep)) + ".tgz"


def _part_archive(runs_dir: str, rel: str, staging: str) -> tuple[bytes, int]:
    """(the gzipped tar of part `rel` saved learner-only with its config.json and metrics.csv, its env step)."""
    from agents import driver

    dest = os.path.join(staging, rel)
    step = driver.learner_only_checkpoint(os.path.join(runs_dir, rel), dest)
    for name in ("config.json", "metrics.csv"):
        if os.path.isfile(os.path.join(runs_dir, rel, name)):
            shutil.copy2(os.path.join(runs_dir, rel, name), dest)
    data = io.BytesIO()
    with tarfile.open(fileobj=data, mode="w:gz") as tar:
        tar.add(dest, arcname=rel)
    return data.getvalue(), step


def bundle_dir(to: str, index: int) -> str:
    """Where `pack` writes bundle `index`: `to` itself for the first, `to/more-<index>` for the others."""
    return to if index == 0 else os.path.join(to, f"more-{index}")


def pack(runs_dir: str, to: str, max_mb: float = PIECE_MB, max_total_mb: float = TOTAL_MB,
         max_files: int = RETURN_FILES, max_all_mb: float = RETURN_MB, runs: list[str] | None = None,
         log=print) -> list[str]:
    """Writes the unfinished parts of `runs_dir` (with `runs`, `<experiment>/<run>` folders, only theirs: two
    commands training different runs side by side each pack their own), learner-only, as `<archive>.NNN` pieces
    in bundles of at most `max_total_mb` each (what one device call's tree carries): the first in `to`, the parts
    that do not fit beside it in `to/more-1`, then `to/more-2`, ... (first fit, the parts with the most steps
    first), so that the next machine's calls carry one bundle each; at most `max_files` pieces and `max_all_mb`
    MiB in all (what a device call brings back), the parts beyond named and left out. The old pieces there are
    removed first; returns the pieces' paths."""
    for name, value in (("max_mb", max_mb), ("max_total_mb", max_total_mb), ("max_all_mb", max_all_mb)):
        if not value > 0:
            raise ValueError(f"{name}={value!r} is invalid: allowed is a number > 0.")
    if not (isinstance(max_files, int) and max_files >= 1):
        raise ValueError(f"max_files={max_files!r} is invalid: allowed is an integer >= 1.")
    os.makedirs(to, exist_ok=True)
    for folder in [to] + [os.path.join(to, d) for d in os.listdir(to)
                          if re.fullmatch(r"more-\d+", d) and os.path.isdir(os.path.join(to, d))]:
        for name in os.listdir(folder):
            if PIECE.fullmatch(name):
                os.remove(os.path.join(folder, name))
        if folder != to and not os.listdir(folder):
            os.rmdir(folder)
    parts = sorted(unfinished_parts(runs_dir, runs), key=lambda rel: -newest_step(os.path.join(runs_dir, rel)))
    size, budget, paths = int(max_mb * 2**20), int(max_total_mb * 2**20), []
    written: list[int] = []  # bytes in each bundle
    with tempfile.TemporaryDirectory() as staging:
        for rel in parts:
            # Under the part's lock: a part another command is training is not packed half-written.
            with part_lock(os.path.join(runs_dir, rel)) as taken:
                if taken is None:
                    try:
                        blob, step = _part_archive(runs_dir, rel, staging)
                    except Exception as error:  # a damaged part must not cost the others their carry
                        taken = f"{type(error).__name__}: {str(error).splitlines()[0] if str(error) else ''}"
            if taken is not None:
                log(f"left out {rel}: {taken}")
                continue
            if len(blob) > budget:
                log(f"left out {rel} at {step:,} env steps: {len(blob) / 2**20:.2f} MiB is more than "
                    f"--max-total-mb {max_total_mb:g}")
                continue
            count, total = -(-len(blob) // size), sum(written) + len(blob)
            if len(paths) + count > max_files or total > max_all_mb * 2**20:
                log(f"left out {rel} at {step:,} env steps: with its {count} piece(s), {len(blob) / 2**20:.1f} MiB, "
                    f"the bundles would pass what a device call brings back ({max_files} files, {max_all_mb:g} MiB)")
                continue
            index = next((i for i, used in enumerate(written) if used + len(blob) <= budget), len(written))
            if index == len(written):
                written.append(0)
            folder = bundle_dir(to, index)
            os.makedirs(folder, exist_ok=True)
            for i in range(0, len(blob), size):
                paths.append(os.path.join(folder, f"{archive_name(rel)}.{i // size:03d}"))
                with open(paths[-1], "wb") as f:
                    f.write(blob[i:i + size])
            written[index] += len(blob)
            log(f"packed {rel} at {step:,} env steps: {len(blob) / 2**20:.1f} MiB"
                + (f", in {folder} (bundle {index + 1}: carry it in a call of its own)" if index else ""))
    if not parts:
        log(f"no unfinished part under {runs_dir}" + (f" in {', '.join(runs)}" if runs is not None else ""))
    elif paths:
        log(f"{len(paths)} piece(s), {sum(written) / 2**20:.1f} MiB, in {len(written)} bundle(s): "
            + ", ".join(f"{bundle_dir(to, i)} {used / 2**20:.1f} MiB" for i, used in enumerate(written)))
    return paths


def _read_archive(source: str, pieces: list[str]) -> bytes:
    """The joined pieces; ValueError if their numbers do not run 000, 001, ... without a gap."""
    indices = [int(PIECE.fullmatch(p)["index"]) for p in pieces]
    if indices != list(range(len(pieces))):
        missing = sorted(set(range(max(indices) + 1)) - set(indices))
        raise ValueError(f"piece {missing[0]:03d} is missing")
    chunks = []
    for name in pieces:
        with open(os.path.join(source, name), "rb") as f:
            chunks.append(f.read())
    return b"".join(chunks)


def _keep_reason(packed_dir: str, target: str) -> str:
    """Why the part folder `target` here is kept rather than replaced by `packed_dir`, or ""."""
    if not os.path.isdir(target):
        return ""
    if os.path.isfile(os.path.join(target, "eval.json")):
        return "it is done here (eval.json)"
    here, packed = newest_step(target), newest_step(packed_dir)
    if here is not None and here >= packed:
        return f"it has a checkpoint at {here:,} env steps here (packed: {packed:,})"
    configs = [os.path.join(d, "config.json") for d in (target, packed_dir)]
    if all(os.path.isfile(c) for c in configs):
        loaded = []
        for c in configs:
            with open(c) as f:
                loaded.append(json.load(f))
        if loaded[0] != loaded[1]:
            return "its config.json here differs from the packed one"
    return ""


def has_pieces(source: str) -> bool:
    """Whether folder `source` holds pieces `pack` writes."""
    return any(PIECE.fullmatch(name) for name in os.listdir(source))


def unpack(source: str, runs_dir: str, log=print) -> list[str]:
    """Puts the parts packed in `source` into `runs_dir` (see the module docstring); returns those put there
    (relative paths)."""
    archives: dict[str, list[str]] = {}
    for name in sorted(os.listdir(source)):
        match = PIECE.fullmatch(name)
        if match:
            archives.setdefault(match["archive"], []).append(name)
    if not archives:
        raise ValueError(f"--from={source!r} holds no <part>.tgz.NNN pieces: allowed is a folder `pack --to` wrote.")
    extracted = []
    for archive, pieces in archives.items():
        with tempfile.TemporaryDirectory() as staging:
            try:
                with tarfile.open(fileobj=io.BytesIO(_read_archive(source, pieces)), mode="r:gz") as tar:
                    tar.extractall(staging, filter="data")
            except Exception as error:  # a missing or damaged piece: gzip, zlib and tarfile raise many types
                log(f"skipped {archive}: {type(error).__name__}: {error}")
                continue
            for rel in unfinished_parts(staging):
                target = os.path.join(runs_dir, rel)
                why = _keep_reason(os.path.join(staging, rel), target)
                if why:
                    log(f"kept {rel}: {why}")
                    continue
                if os.path.isdir(target):
                    shutil.rmtree(target)
                shutil.copytree(os.path.join(staging, rel), target)
                extracted.append(rel)
                log(f"unpacked {rel} at {newest_step(target):,} env steps")
    return extracted


def main(argv=None) -> int:
    p = argparse.ArgumentParser(prog="python -m tools.carry_parts", description=__doc__.split("\n\n")[0])
    p.add_argument("action", choices=("pack", "unpack"))
    p.add_argument("names", nargs="*", help="pack: only the parts of these experiments or experiment/run names "
                                            "(default: every unfinished part)")
    p.add_argument("--runs-dir", default=os.path.join("runs", "experiments"),
                   help="the experiments' runs folder (default runs/experiments)")
    p.add_argument("--to", help="pack: the folder for the pieces (carry it to the next machine in a git-ignored "
                                "folder of the repository)")
    p.add_argument("--from", dest="source", help="unpack: the folder holding the pieces")
    p.add_argument("--max-mb", type=float, help=f"pack: the largest piece in MiB (default {PIECE_MB:g})")
    p.add_argument("--max-total-mb", type=float,
                   help=f"pack: each bundle's total in MiB, what one call carries (default {TOTAL_MB:g}); first fit, "
                        "the parts with the most steps first")
    args = p.parse_intermixed_args(argv)  # names after the options too
    if args.action == "pack":
        if args.to is None or args.source is not None:
            raise ValueError("pack needs --to DIR (and no --from): allowed is `pack --to DIR`.")
        pack(args.runs_dir, args.to, PIECE_MB if args.max_mb is None else args.max_mb,
             TOTAL_MB if args.max_total_mb is None else args.max_total_mb,
             runs=run_folders(select(args.names)) if args.names else None)
    else:
        if (args.source is None or args.to is not None or args.max_total_mb is not None or args.max_mb is not None
                or args.names):
            raise ValueError("unpack needs --from DIR (and no names, --to, --max-mb or --max-total-mb): allowed is "
                             "`unpack --from DIR`.")
        unpack(args.source, args.runs_dir)
    return 0


if __name__ == "__main__":
    from tools import run_cli

    run_cli(main)
