"""Helpers for tests that submit jobs to a Slurm cluster (through submitit).

Usage in a test::

    from slurm_cluster import ensure_slurm
    ok, why = ensure_slurm()
    if not ok:
        pytest.skip(why)

``ensure_slurm`` starts the single-node cluster of ``.ci/slurm.sh`` when Slurm is installed but
not running and we are root (CI runs that script itself, see ``.ci/run``). No accounting DB is
configured there, so ``sacct`` (and therefore ``job.state`` in submitit) does not work: wait for
jobs with a deadline and ``job.done()``, and read states with ``scontrol show job``.
"""

from __future__ import annotations

import os
import shutil
import subprocess
from pathlib import Path

SLURM_SH = Path(__file__).resolve().parents[1] / ".ci" / "slurm.sh"
# Daemons live in sbin, which a user's PATH may lack.
_PATH = os.pathsep.join([os.environ.get("PATH", ""), "/usr/sbin", "/sbin", "/usr/local/sbin"])


def _first_line(text: str) -> str:
    lines = [line.strip() for line in (text or "").splitlines() if line.strip()]
    return lines[0] if lines else "no output"


def _error_line(text: str) -> str:
    """The script's own `ERROR:` line if there is one, else the last line."""
    lines = [line.strip() for line in (text or "").splitlines() if line.strip()]
    errors = [line for line in lines if "ERROR:" in line]
    return (errors or lines or ["no output"])[-1]


def slurm_available() -> tuple[bool, str]:
    """(True, "...") when `sinfo` answers and some node is idle or mixed, else (False, one-line reason)."""
    if shutil.which("sinfo") is None:
        return False, "sinfo not installed"
    try:
        p = subprocess.run(["sinfo", "-h", "-N", "-o", "%N %t"], capture_output=True, text=True, timeout=30)
    except subprocess.TimeoutExpired:
        return False, "slurmctld not responding: sinfo timed out after 30 s"
    if p.returncode != 0:
        return False, f"slurmctld not responding: {_first_line(p.stderr or p.stdout)}"
    nodes = [line.split() for line in p.stdout.splitlines() if len(line.split()) == 2]
    # Compact states: idle, mix, alloc, drain, down, ...; a trailing '*' means "not responding".
    usable = [name for name, state in nodes if state.rstrip("-") in ("idle", "mix")]
    if usable:
        return True, f"slurm node {usable[0]} is available"
    listed = ", ".join(f"{name}={state}" for name, state in nodes) or "no nodes"
    return False, f"no idle Slurm node ({listed})"


def ensure_slurm() -> tuple[bool, str]:
    """slurm_available(), after starting the local cluster with .ci/slurm.sh if that is needed and possible."""
    ok, why = slurm_available()
    if ok:
        return ok, why
    if shutil.which("slurmctld", path=_PATH) is None or shutil.which("sinfo") is None:
        return False, f"{why} (Slurm is not installed: apt-get install slurm-wlm munge)"
    if os.geteuid() != 0:
        return False, f"{why} (not root, so not starting it; run `sudo bash {SLURM_SH}`)"
    try:  # The script is idempotent and serialises concurrent calls (e.g. pytest-xdist workers).
        p = subprocess.run(
            ["bash", str(SLURM_SH)],
            capture_output=True,
            text=True,
            timeout=180,
            env={**os.environ, "PATH": _PATH},
        )
    except subprocess.TimeoutExpired:
        return False, f"{why}; {SLURM_SH.name} did not finish within 180 s"
    if p.returncode != 0:
        return False, f"{why}; {SLURM_SH.name} failed: {_error_line(p.stderr + p.stdout)}"
    return slurm_available()
