"""agents/provenance.py: the command, code version, device and date that results files carry."""

import datetime
import os

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
