"""Every results JSON under results/ names what made it: the command, the code version, the device and the date
(`agents/provenance.py` writes them; files from before it carry them backfilled, saying where the evidence was
missing). A key counts at the top level, inside `meta` or inside `provenance`.

Not results files, so not checked: results/index.json (the index of the tables), every config.json (a run's
training config) and job.json (a scheduler's job record), the shipped policies under results/checkpoints/, and
the train.py logdir files under results/runs/ other than eval JSONs. A table.json's top-level device is not
asked for: a table is built from runs on several devices, and its rows name each seed's."""

import functools
import glob
import json
import os

import pytest

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
KEYS = ("command", "code", "device", "date")


def is_results_file(path: str) -> bool:
    """`path` relative to the repository root, "/"-separated."""
    name = os.path.basename(path)
    if path == "results/index.json" or name in ("config.json", "job.json"):
        return False
    if path.startswith("results/checkpoints/"):
        return False
    if path.startswith("results/runs/") and path.count("/") >= 3 and not name.startswith("eval"):
        return False
    return True


def results_files() -> list[str]:
    paths = glob.glob(os.path.join(ROOT, "results", "**", "*.json"), recursive=True)
    return sorted(p for p in (os.path.relpath(p, ROOT).replace(os.sep, "/") for p in paths) if is_results_file(p))


@functools.lru_cache(maxsize=None)
def _load(path: str) -> dict:
    with open(os.path.join(ROOT, path)) as f:
        return json.load(f)


def carried(data: dict, key: str):
    """The value of `key` at the top level, in `meta` or in `provenance` (None if none has it)."""
    for where in (data, data.get("meta"), data.get("provenance")):
        if isinstance(where, dict) and where.get(key) not in (None, ""):
            return where[key]
    return None


FILES = results_files()
CHECKS = [(path, key) for path in FILES for key in KEYS
          if not (key == "device" and os.path.basename(path) == "table.json")]


def test_the_scan_finds_the_results_and_skips_what_is_not_one():
    assert len(FILES) > 300
    assert "results/headline/ur5e_reach_ppo_eval.json" in FILES
    assert not any(p == "results/index.json" or p.endswith(("/config.json", "/job.json")) for p in FILES)
    assert not any(p.startswith("results/checkpoints/") for p in FILES)
    assert is_results_file("results/runs/some-run/eval.json")
    assert not is_results_file("results/runs/some-run/x.json")


@pytest.mark.parametrize("path,key", CHECKS, ids=[f"{p}:{k}" for p, k in CHECKS])
def test_a_results_file_names_what_made_it(path, key):
    assert carried(_load(path), key), (
        f"{path} lacks {key!r} (at the top level, in meta or in provenance): every results file carries the "
        f"command, code, device and date (agents/provenance.py's stamp); where the evidence is missing, the value "
        f"says so")
