"""The notebooks under notebooks/ run top to bottom without a cell error, in their small settings.

Each runs in a fresh Jupyter kernel of this interpreter (nbclient, kernel "python3") with
REACH_NOTEBOOK_SMALL=1, its outputs under a temporary directory and the tests' compilation cache
(conftest.py). Almost all of their time is XLA compiling MJX programs, which uses one core: the
notebooks therefore run two at a time (REACH_NOTEBOOK_JOBS), which on 2 cores takes about 60 % of
the time of running them one after the other.
"""

import asyncio
import os
import pathlib
import time

import nbformat
import pytest
from nbclient import NotebookClient

ROOT = pathlib.Path(__file__).resolve().parent.parent
NOTEBOOKS = sorted((ROOT / "notebooks").glob("*.ipynb"))
CELL_TIMEOUT = 600
"""Seconds one cell may run: a guard against hangs, not a speed check. The longest, a small training run or
four evaluations, take ~100 s cold alone, but on a 2-core CI machine they share the cores with the other
notebook and pytest-xdist's other worker: 03's four evaluations once ran past 300 s beside Brax's PPO test."""
NOTEBOOK_TIMEOUT = 900
"""Seconds one notebook may run, kernel start included (a hang guard, as above)."""
JOBS = int(os.environ.get("REACH_NOTEBOOK_JOBS", "2"))
LONGEST_FIRST = ["03_evaluate_checkpoints.ipynb", "01_quickstart.ipynb", "04_environment_tour.ipynb",
                 "02_edit_an_algorithm.ipynb"]
"""Start order (cold: ~130, ~80, ~30, ~25 s alone), so that the short ones fill in beside the long ones."""


async def _execute(path: pathlib.Path, slots: asyncio.Semaphore) -> tuple[Exception | None, float]:
    async with slots:
        notebook = nbformat.read(path, as_version=4)
        client = NotebookClient(notebook, timeout=CELL_TIMEOUT, kernel_name="python3",
                                resources={"metadata": {"path": str(path.parent)}})
        start = time.perf_counter()
        try:
            await asyncio.wait_for(client.async_execute(), NOTEBOOK_TIMEOUT)
            error = None
        except Exception as exc:  # a cell's error (CellExecutionError), a timeout, a dead kernel
            error = exc
        return error, time.perf_counter() - start


@pytest.fixture(scope="module")
def executed(tmp_path_factory):
    """{notebook name: (error or None, seconds)} of every notebook, executed in small settings."""
    env = {"REACH_NOTEBOOK_SMALL": "1", "REACH_NOTEBOOK_RUNS": str(tmp_path_factory.mktemp("notebook_runs")),
           "JAX_COMPILATION_CACHE_DIR": os.environ.get("JAX_COMPILATION_CACHE_DIR", str(ROOT / ".jax_cache"))}

    order = sorted(NOTEBOOKS, key=lambda p: LONGEST_FIRST.index(p.name) if p.name in LONGEST_FIRST else len(NOTEBOOKS))

    async def run_all():
        slots = asyncio.Semaphore(JOBS)  # asyncio wakes waiters in order: notebooks start in `order`
        return await asyncio.gather(*(_execute(path, slots) for path in order))

    with pytest.MonkeyPatch.context() as patch:  # the kernels inherit this process's environment
        for name, value in env.items():
            patch.setenv(name, value)
        # `import jax` here set it to 1; unset, the notebooks silence XLA's spurious cache-load errors.
        patch.delenv("TF_CPP_MIN_LOG_LEVEL", raising=False)
        results = asyncio.run(run_all())
    return {path.name: result for path, result in zip(order, results)}


def test_the_four_notebooks_are_there_without_outputs():
    assert [p.name for p in NOTEBOOKS] == ["01_quickstart.ipynb", "02_edit_an_algorithm.ipynb",
                                          "03_evaluate_checkpoints.ipynb", "04_environment_tour.ipynb"]
    for path in NOTEBOOKS:
        notebook = nbformat.read(path, as_version=4)
        nbformat.validate(notebook)
        assert notebook.metadata.kernelspec.name == "python3", path.name
        code = [cell for cell in notebook.cells if cell.cell_type == "code"]
        assert "REACH_NOTEBOOK_SMALL" in code[0].source, f"{path.name}: the first code cell reads the size switch"
        for cell in code:  # committed without outputs: the repository stays small
            assert cell.outputs == [] and cell.execution_count is None, f"{path.name} has outputs: clear them"


@pytest.mark.parametrize("name", [p.name for p in NOTEBOOKS])
def test_notebook_runs_without_error(executed, name):
    error, seconds = executed[name]
    print(f"{name}: {seconds:.0f} s")
    if error is not None:
        pytest.fail(f"{name} failed after {seconds:.0f} s: {type(error).__name__}:\n{error}", pytrace=False)
