"""agents/provenance.py: the command, code version, device and date that results files carry."""

import datetime
import os
import subprocess

import pytest

from agents import provenance


def test_the_command_is_written_as_a_user_types_it(monkeypatch):
    monkeypatch.delenv(provenance.COMMAND_VARIABLE, raising=False)
    module = os.path.join(provenance.ROOT, "tools", "experiments.py")
    assert provenance.command([module, "launch", "reward"]) == "python -m tools.experiments launch reward"
    assert provenance.command(["train.py", "ur5e-reach-ppo", "--logdir", "a b"]) == "python train.py ur5e-reach-ppo --logdir 'a b'"


def test_a_launcher_names_the_command_of_its_jobs(monkeypatch):
    monkeypatch.setenv(provenance.COMMAND_VARIABLE, "python -m tools.experiments launch reward")
    assert provenance.command() == "python -m tools.experiments launch reward"


def test_the_stamp_holds_code_device_and_date(monkeypatch):
    monkeypatch.setenv("REACH_AVOID_CODE_VERSION", "abc1234")
    made = provenance.stamp("python eval.py --checkpoint x")
    assert made == {"command": "python eval.py --checkpoint x", "code": "abc1234",
                    "device": f"CPU, {os.cpu_count()} cores", "date": datetime.date.today().isoformat()}


def _git(root, *args: str) -> str:
    """`git args` in `root` (with an author for commits); its output."""
    return subprocess.run(["git", "-c", "user.name=t", "-c", "user.email=t@t", *args], cwd=root, check=True,
                          capture_output=True, text=True).stdout.strip()


@pytest.fixture
def checkout(tmp_path, monkeypatch):
    """A git checkout with one code file and one results file, both committed: (root, its short commit)."""
    monkeypatch.delenv("REACH_AVOID_CODE_VERSION", raising=False)
    (tmp_path / "results").mkdir()
    (tmp_path / "env.py").write_text("x = 1\n")
    (tmp_path / "results" / "table.md").write_text("| a |\n")
    _git(tmp_path, "init", "-q")
    _git(tmp_path, "add", ".")
    _git(tmp_path, "commit", "-q", "-m", "start")
    return tmp_path, _git(tmp_path, "rev-parse", "--short", "HEAD")


def test_a_clean_checkout_is_its_commit(checkout):
    root, commit = checkout
    assert provenance.code_version(str(root)) == commit


def test_an_edited_code_file_marks_the_version_modified(checkout):
    root, commit = checkout
    (root / "env.py").write_text("x = 2\n")
    assert provenance.code_version(str(root)) == commit + "+modified"


def test_a_deleted_results_file_leaves_the_version_as_it_is(checkout):
    root, commit = checkout
    (root / "results" / "table.md").unlink()
    assert provenance.code_version(str(root)) == commit


def test_a_copy_without_git_is_unknown(tmp_path, monkeypatch):
    monkeypatch.delenv("REACH_AVOID_CODE_VERSION", raising=False)
    monkeypatch.setenv("GIT_CEILING_DIRECTORIES", str(tmp_path.parent))
    assert provenance.code_version(str(tmp_path)) == "unknown"
