"""Carries the unfinished parts of `tools.experiments` runs from one machine to the next. A GPU machine lent
for half an hour goes back with its `runs/`, and a part trained half way (by a `run --time-limit` call that ended
first) is lost with it; these few MB let the next machine resume it.

    python -m tools.carry_parts pack --runs-dir runs/experiments --to $OUT/carry     # the last call on a machine
    python -m tools.carry_parts unpack --from DIR --runs-dir runs/experiments        # the first call on the next

`pack` takes every part folder (`<experiment>/<run>/seeds-<first>-<last>/`) that has a checkpoint and no
`eval.json` (not done), saves its newest checkpoint learner-only (`agents.driver.learner_only_checkpoint`: no
env states, no replay buffer) beside its `config.json` and `metrics.csv`, and writes them as one gzipped tar
split into pieces of at most `--max-mb` (`parts.tgz.000`, ...: a device call brings back files of at most 16 MiB).
A resume from it starts fresh episodes and, for SAC, refills the replay buffer: not bit-for-bit the run that
would have gone on, the same as any learner-only resume. `unpack` joins the pieces and extracts each part
whose folder here has no checkpoint at that step or later.
"""

from __future__ import annotations

import argparse
import io
import os
import re
import shutil
import tarfile
import tempfile

PIECE = "parts.tgz"
PART_DIR = re.compile(r"seeds-\d+-\d+")


def unfinished_parts(runs_dir: str) -> list[str]:
    """The part folders under `runs_dir` (relative, `<experiment>/<run>/seeds-F-L`) with a checkpoint and no
    eval.json, sorted."""
    found = []
    for root, dirs, files in os.walk(runs_dir):
        if PART_DIR.fullmatch(os.path.basename(root)):
            dirs[:] = []
            if "eval.json" not in files and newest_step(root) is not None:
                found.append(os.path.relpath(root, runs_dir))
    return sorted(found)


def newest_step(part_dir: str) -> int | None:
    """The largest env step among `part_dir/checkpoints/<step>/` folders, None if there is none."""
    folder = os.path.join(part_dir, "checkpoints")
    steps = [int(name) for name in os.listdir(folder) if name.isdigit()] if os.path.isdir(folder) else []
    return max(steps) if steps else None


def pack(runs_dir: str, to: str, max_mb: float = 15.0, log=print) -> list[str]:
    """Writes the unfinished parts of `runs_dir` learner-only into `to/parts.tgz.NNN`; returns the pieces'
    paths (none if no part is unfinished)."""
    from agents import driver

    if not max_mb > 0:
        raise ValueError(f"max_mb={max_mb!r} is invalid: allowed is a number > 0.")
    parts = unfinished_parts(runs_dir)
    if not parts:
        log(f"no unfinished part under {runs_dir}")
        return []
    with tempfile.TemporaryDirectory() as staging:
        for rel in parts:
            dest = os.path.join(staging, rel)
            step = driver.learner_only_checkpoint(os.path.join(runs_dir, rel), dest)
            for name in ("config.json", "metrics.csv"):
                if os.path.isfile(os.path.join(runs_dir, rel, name)):
                    shutil.copy2(os.path.join(runs_dir, rel, name), dest)
            log(f"packed {rel} at {step:,} env steps")
        data = io.BytesIO()
        with tarfile.open(fileobj=data, mode="w:gz") as tar:
            for rel in parts:
                tar.add(os.path.join(staging, rel), arcname=rel)
    os.makedirs(to, exist_ok=True)
    blob, size = data.getvalue(), int(max_mb * 2**20)
    paths = []
    for i in range(0, len(blob), size):
        paths.append(os.path.join(to, f"{PIECE}.{i // size:03d}"))
        with open(paths[-1], "wb") as f:
            f.write(blob[i:i + size])
    log(f"{len(parts)} parts, {len(blob) / 2**20:.1f} MiB in {len(paths)} pieces under {to}")
    return paths


def unpack(source: str, runs_dir: str, log=print) -> list[str]:
    """Extracts the parts packed in `source/parts.tgz.*` into `runs_dir`, except those whose folder there has a
    checkpoint at the packed step or later; returns the parts extracted (relative paths)."""
    pieces = sorted(name for name in os.listdir(source) if re.fullmatch(re.escape(PIECE) + r"\.\d{3}", name))
    if not pieces:
        raise ValueError(f"--from={source!r} holds no {PIECE}.NNN pieces: allowed is the folder `pack --to` wrote.")
    blob = b"".join(open(os.path.join(source, name), "rb").read() for name in pieces)
    extracted = []
    with tempfile.TemporaryDirectory() as staging:
        with tarfile.open(fileobj=io.BytesIO(blob), mode="r:gz") as tar:
            tar.extractall(staging, filter="data")
        for rel in unfinished_parts(staging):
            packed, here = newest_step(os.path.join(staging, rel)), newest_step(os.path.join(runs_dir, rel))
            if here is not None and here >= packed:
                log(f"kept {rel}: it has a checkpoint at {here:,} env steps here (packed: {packed:,})")
                continue
            target = os.path.join(runs_dir, rel)
            if os.path.isdir(target):
                shutil.rmtree(target)
            shutil.copytree(os.path.join(staging, rel), target)
            extracted.append(rel)
            log(f"unpacked {rel} at {packed:,} env steps")
    return extracted


def main(argv=None) -> int:
    p = argparse.ArgumentParser(prog="python -m tools.carry_parts", description=__doc__.split("\n\n")[0])
    p.add_argument("action", choices=("pack", "unpack"))
    p.add_argument("--runs-dir", default=os.path.join("runs", "experiments"),
                   help="the experiments' runs folder (default runs/experiments)")
    p.add_argument("--to", help="pack: the folder for the pieces")
    p.add_argument("--from", dest="source", help="unpack: the folder holding the pieces")
    p.add_argument("--max-mb", type=float, default=15.0, help="pack: the largest piece in MiB (default 15)")
    args = p.parse_args(argv)
    if args.action == "pack":
        if args.to is None or args.source is not None:
            raise ValueError("pack needs --to DIR (and no --from): allowed is `pack --to DIR`.")
        pack(args.runs_dir, args.to, args.max_mb)
    else:
        if args.source is None or args.to is not None:
            raise ValueError("unpack needs --from DIR (and no --to): allowed is `unpack --from DIR`.")
        unpack(args.source, args.runs_dir)
    return 0


if __name__ == "__main__":
    from tools import run_cli

    run_cli(main)
