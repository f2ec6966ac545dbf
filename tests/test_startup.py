"""What an evaluation of a shipped policy imports: distrax (TensorFlow Probability's JAX substrate) and orbax take
about a second to import and an evaluation by the policy's mode needs neither (eval.py's start-up,
results/time_to_result)."""

import subprocess
import sys

import pytest

PROGRAM = """
import sys
import envs
from agents import evaluation
policy = evaluation.checkpoint_policy("results/checkpoints/ur5e-reach-ppo")
config = envs.make_config(policy.train_env_name, policy.train_env_config, episode_length=2, substeps=2)
evaluation.run(policy, policy.train_env_name, config, num_envs=2)
print("imported:" + ",".join(sorted({name.split(".")[0] for name in sys.modules if name.split(".")[0] in ("distrax", "orbax")})))
"""


@pytest.fixture(scope="module")
def imported() -> set:
    out = subprocess.run([sys.executable, "-c", PROGRAM], capture_output=True, text=True, check=True)
    line = [text for text in out.stdout.splitlines() if text.startswith("imported:")][-1]
    return set(filter(None, line[len("imported:"):].split(",")))


def test_an_evaluation_by_the_mode_does_not_import_distrax(imported):
    assert "distrax" not in imported


def test_an_evaluation_of_an_export_does_not_import_orbax(imported):
    assert "orbax" not in imported
