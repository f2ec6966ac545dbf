"""The notebooks under notebooks/ run top to bottom without a cell error, in their small settings.

Each runs in a fresh Jupyter kernel of this interpreter (nbclient, kernel "python3") with
REACH_NOTEBOOK_SMALL=1, its outputs under a temporary directory and the tests' compilation cache
(conftest.py). Almost all of their time is XLA compiling MJX programs, which uses one core: the
notebooks therefore run two at a time (REACH_NOTEBOOK_JOBS), which on 2 cores takes about 60 % of
the time of running them one after the other.
"""

import ast
import asyncio
import importlib.metadata
import json
import os
import pathlib
import re
import sys
import time
import tomllib

import nbformat
import pytest
from nbclient import NotebookClient
from limits import HANG_GUARD_S

ROOT = pathlib.Path(__file__).resolve().parent.parent
NOTEBOOKS = sorted((ROOT / "notebooks").glob("*.ipynb"))
CELL_TIMEOUT = HANG_GUARD_S
"""Seconds one cell may run: a hang guard, not a speed check (tests/limits.py)."""
NOTEBOOK_TIMEOUT = HANG_GUARD_S
"""Seconds one notebook may run, kernel start included (a hang guard, as above)."""
JOBS = int(os.environ.get("REACH_NOTEBOOK_JOBS", "2"))
LONGEST_FIRST = ["03_evaluate_checkpoints.ipynb", "01_quickstart.ipynb", "04_environment_tour.ipynb",
                 "02_edit_an_algorithm.ipynb"]
"""Start order (cold: ~130, ~80, ~30, ~25 s alone), so that the short ones fill in beside the long ones."""


async def _execute(path: pathlib.Path, slots: asyncio.Semaphore) -> tuple[Exception | None, float, nbformat.NotebookNode]:
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
        return error, time.perf_counter() - start, notebook


@pytest.fixture(scope="module")
def executed(tmp_path_factory):
    """{notebook name: (error or None, seconds, the executed notebook)} of every notebook, in small settings."""
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
            assert cell.outputs == [], f"{path.name} has outputs: clear them"
            assert cell.execution_count is None, f"{path.name} has execution counts: clear them"


@pytest.mark.parametrize("name", [p.name for p in NOTEBOOKS])
def test_notebook_runs_without_error(executed, name):
    error, seconds, _ = executed[name]
    print(f"{name}: {seconds:.0f} s")
    if error is not None:
        pytest.fail(f"{name} failed after {seconds:.0f} s: {type(error).__name__}:\n{error}", pytrace=False)


def _outputs(notebook) -> list:
    return [out for cell in notebook.cells if cell.cell_type == "code" for out in cell.get("outputs", [])]


@pytest.mark.parametrize("name", [p.name for p in NOTEBOOKS])
def test_notebook_shows_a_picture(executed, name):
    """Every notebook draws something when run: a plot, a rendered frame or a clip (an image output)."""
    images = [out for out in _outputs(executed[name][2]) if set(out.get("data", {})) & {"image/png", "image/gif"}]
    assert images, f"{name} ran without an image output"


@pytest.mark.parametrize("name", ["01_quickstart.ipynb", "03_evaluate_checkpoints.ipynb"])
def test_evaluating_notebook_shows_a_table_with_intervals(executed, name):
    """The evaluation tables give mean ± std with the mean's interval in brackets over several trained seeds."""
    tables = [out["data"]["text/markdown"] for out in _outputs(executed[name][2])
              if "text/markdown" in out.get("data", {}) and "|" in out["data"]["text/markdown"]]
    assert any(re.search(r"± [0-9.]+ \[[0-9.]+, [0-9.]+\]", t) for t in tables), f"{name}: no table with intervals"


@pytest.mark.parametrize("path", NOTEBOOKS, ids=lambda p: p.name)
def test_notebook_opens_with_what_it_shows_and_its_cpu_time(path):
    first = nbformat.read(path, as_version=4).cells[0]
    assert first.cell_type == "markdown", path.name
    assert first.source.startswith("# "), path.name
    assert re.search(r"2-core CPU", first.source), f"{path.name}: the first cell states its time on a CPU"


def test_every_committed_cell_has_an_id():
    """nbformat 4.5 cell ids, in the file itself (a cell without one warns MissingIDFieldWarning on every read)."""
    for path in NOTEBOOKS:
        cells = json.loads(path.read_text())["cells"]
        assert all("id" in cell for cell in cells), path.name


PROJECT = {"envs", "agents", "tools", "benchmarks"}


def _imports(source: str) -> tuple[set[str], set[str]]:
    """(top-level third-party or stdlib names, project modules "pkg.mod") that `source` imports anywhere."""
    names, project = set(), set()
    for node in ast.walk(ast.parse(source)):
        if isinstance(node, ast.Import):
            modules = [alias.name for alias in node.names]
        elif isinstance(node, ast.ImportFrom) and node.level == 0:
            modules = [node.module] + [f"{node.module}.{alias.name}" for alias in node.names]
        else:
            continue
        for module in modules:
            (project if module.split(".")[0] in PROJECT else names).add(module if module.split(".")[0] in PROJECT
                                                                         else module.split(".")[0])
    return names, project


def _notebook_source(path: pathlib.Path) -> str:
    cells = nbformat.read(path, as_version=4).cells
    lines = [line for cell in cells if cell.cell_type == "code" for line in cell.source.splitlines()]
    return "\n".join(line for line in lines if not line.lstrip().startswith(("%", "!")))  # IPython magics


def _distribution(requirement: str) -> str:
    return re.split(r"[<>=!~\[; ]", requirement, maxsplit=1)[0].lower().replace("_", "-")


def test_the_notebook_extra_installs_what_the_notebooks_import():
    """Every package the notebooks import, directly or through the project modules they import, is a core
    dependency or in the `notebook` extra (pyproject.toml), so `pip install -e ".[notebook]"` runs them."""
    with open(ROOT / "pyproject.toml", "rb") as f:
        project = tomllib.load(f)["project"]
    allowed = {_distribution(r) for r in project["dependencies"] + project["optional-dependencies"]["notebook"]}
    names, modules = set(), set()
    for path in NOTEBOOKS:
        found, used = _imports(_notebook_source(path))
        names, modules = names | found, modules | used
    for module in modules:  # one level down: the project modules the notebooks use
        file = ROOT / (module.replace(".", "/") + ".py")
        if file.exists():
            names |= _imports(file.read_text())[0]
    distributions = importlib.metadata.packages_distributions()
    third_party = sorted(n for n in names if n not in sys.stdlib_module_names and n != "__future__")
    assert {"matplotlib", "jax", "IPython"} <= set(third_party)  # the scan sees the notebooks' own imports
    missing = [n for n in third_party
               if not any(_distribution(d) in allowed for d in distributions.get(n, [n]))]
    assert missing == [], f"imported by the notebooks but installed by neither the core nor the notebook extra: {missing}"
