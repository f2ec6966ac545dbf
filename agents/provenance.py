"""What made a result: the command, the code version, the device and the date, written into every results file
(a run's eval.json, eval.py's report, the experiment tables) so that a reader can tell where a number comes from."""

from __future__ import annotations

import datetime
import os
import shlex
import subprocess
import sys

import jax

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
COMMAND_VARIABLE = "REACH_AVOID_COMMAND"
"""Set by a launcher for the processes it starts (a scheduler's job runs a bootstrap, not the user's command)."""


RESULTS_FOLDER = "results"
"""Where results are written: its files are outputs, not code, and leave the code version as it is."""


def code_version(root: str = ROOT) -> str:
    """The git commit of the checkout at `root`, "+modified" if tracked files outside results/ differ from it (a result
    written or edited there changes no code). A copy without .git says "unknown" unless REACH_AVOID_CODE_VERSION
    names it."""
    if os.environ.get("REACH_AVOID_CODE_VERSION"):
        return os.environ["REACH_AVOID_CODE_VERSION"]
    try:
        commit = subprocess.run(["git", "rev-parse", "--short", "HEAD"], cwd=root, capture_output=True, text=True,
                                timeout=10, check=True).stdout.strip()
        dirty = subprocess.run(["git", "status", "--porcelain", "--untracked-files=no", "--", ".",
                                f":(exclude){RESULTS_FOLDER}"], cwd=root, capture_output=True, text=True, timeout=10,
                               check=True).stdout.strip()
    except (OSError, subprocess.SubprocessError):
        return "unknown"
    return commit + ("+modified" if dirty else "")


def device_description() -> str:
    """"GPU (NVIDIA H200)", "CPU, 2 cores": the first device jax computes on."""
    d = jax.devices()[0]
    kind = getattr(d, "device_kind", d.platform)
    text = f"{d.platform.upper()} ({kind})" if kind.lower() != d.platform else d.platform.upper()
    if d.platform == "cpu":
        text += f", {os.cpu_count()} cores"
    return text


def command(argv: list[str] | None = None) -> str:
    """The command that made this process's results: $REACH_AVOID_COMMAND where a launcher set it, else `python
    <script> <args>` (`python -m <module>` for a module of this repository run with -m)."""
    if argv is None and os.environ.get(COMMAND_VARIABLE):
        return os.environ[COMMAND_VARIABLE]
    argv = list(sys.argv if argv is None else argv)
    script = os.path.relpath(os.path.abspath(argv[0]), ROOT) if argv and argv[0] else ""
    head = ["python", script]
    if script.endswith(".py") and os.sep in script and not script.startswith(".."):
        head = ["python", "-m", script[:-3].replace(os.sep, ".")]
    return shlex.join(head + argv[1:])


def stamp(command_line: str | None = None) -> dict:
    """{"command", "code", "device", "date"} of this process (`command_line` replaces the detected command)."""
    return {"command": command_line or command(), "code": code_version(), "device": device_description(),
            "date": datetime.date.today().isoformat()}
