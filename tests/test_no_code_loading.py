"""Nothing a run, an export or a config file holds is run as code: loading an export whose arrays hold a pickled
object refuses it without unpickling, and no module of the product calls a code-loading function on data."""

import pathlib
import re
import shutil

import numpy as np
import pytest

from agents import export

ROOT = pathlib.Path(__file__).resolve().parent.parent
SHIPPED = ROOT / "results" / "checkpoints" / "ur5e-reach-ppo"
MARKER = "code_ran.txt"


class _Payload:
    """Unpickling this writes MARKER into the working directory: proof that loading ran code."""

    def __reduce__(self):
        return (pathlib.Path(MARKER).write_text, ("unpickled",))


def test_an_export_with_a_pickled_object_is_refused_unread(tmp_path, monkeypatch):
    monkeypatch.chdir(tmp_path)
    copy = tmp_path / "export"
    shutil.copytree(SHIPPED, copy)
    with np.load(copy / "policy.npz") as data:
        arrays = {k: data[k] for k in data.files}
    first = sorted(arrays)[0]
    arrays[first] = np.array([_Payload()], dtype=object)  # saved pickled: np.savez allows it on writing
    np.savez(copy / "policy.npz", **arrays)
    with pytest.raises(export.CorruptExport, match="policy.npz"):
        export.load(str(copy))
    assert not (tmp_path / MARKER).exists()


CODE_LOADING = re.compile(r"\bpickle\.loads?\(|\bcloudpickle\.loads?\(|\beval\(|\bexec\(|yaml\.load\(|"
                          r"yaml\.unsafe_load|allow_pickle\s*=\s*True|shell\s*=\s*True|\bmarshal\.loads?\(")
"""Calls that would run code held in data (`ast.literal_eval` and `yaml.safe_load` do not match)."""


def _product_files():
    for folder in ("agents", "envs", "tools", "benchmarks"):
        yield from sorted((ROOT / folder).rglob("*.py"))
    yield ROOT / "train.py"
    yield ROOT / "eval.py"


@pytest.mark.parametrize("path", list(_product_files()), ids=lambda p: str(p.relative_to(ROOT)))
def test_no_product_module_loads_code_from_data(path):
    found = [f"{i}: {line.strip()}" for i, line in enumerate(path.read_text().splitlines(), 1)
             if CODE_LOADING.search(line) and "literal_eval" not in line]
    assert not found, f"{path.relative_to(ROOT)}: {found}"


def test_the_scan_finds_a_code_loading_call():
    assert CODE_LOADING.search("cfg = yaml.load(open(p))")
    assert CODE_LOADING.search("subprocess.run(cmd, shell=True)")
    assert not CODE_LOADING.search("value = ast.literal_eval(text)")
