"""The final evaluation compiled in a thread while the run trains (`agents.driver.evaluates_ahead`, on by itself on an
accelerator): forced on here on the CPU, the evaluation at the end traces and compiles nothing, and its numbers are
those of the same run evaluated without it."""

import threading

import jax
import pytest

from agents import driver, presets
from agents.loop import Ahead

RUN = dict(num_timesteps=10_240, seeds=1, log_every=5_120, tensorboard=False, progress=False)
"""Two chunks of the point-mass PPO preset."""
EVENTS = []
"""Every compile event of JAX (tracing, lowering, compiling, or a persistent-cache hit), in order."""
jax.monitoring.register_event_duration_secs_listener(
    lambda name, seconds, **kwargs: EVENTS.append(name) if name.startswith(("/jax/core/compile/",
                                                                           "/jax/compilation_cache/")) else None)


def train(tmp_path, monkeypatch, ahead: bool, eval_envs: int, name: str):
    """(the run's result, the compile events during its final evaluation's call)."""
    monkeypatch.setattr(driver, "evaluates_ahead", lambda *args: ahead)
    during = []
    evaluate = driver.evaluate

    def counted(programs, state, config):
        before = len(EVENTS)
        out = evaluate(programs, state, config)
        during.extend(EVENTS[before:])
        return out

    monkeypatch.setattr(driver, "evaluate", counted)
    config = presets.make_config("point-mass-ppo", logdir=str(tmp_path / name), eval_envs=eval_envs, **RUN)
    return driver.train(config), during


def test_without_it_the_evaluation_compiles_when_called(tmp_path, monkeypatch):
    """The control: the count sees a first call compile (an evaluation size no other test builds)."""
    _, during = train(tmp_path, monkeypatch, ahead=False, eval_envs=23, name="plain")
    assert len(during) > 0


@pytest.fixture(scope="module")
def ahead_run(tmp_path_factory):
    with pytest.MonkeyPatch.context() as monkeypatch:
        return train(tmp_path_factory.mktemp("ahead"), monkeypatch, ahead=True, eval_envs=29, name="ahead")


def test_with_it_the_evaluation_compiles_nothing_when_called(ahead_run):
    _, during = ahead_run
    assert during == []


def test_with_it_the_evaluation_gives_the_same_numbers(ahead_run, tmp_path, monkeypatch):
    result, _ = ahead_run
    plain, _ = train(tmp_path, monkeypatch, ahead=False, eval_envs=29, name="plain")
    assert result.eval_metrics == plain.eval_metrics


def test_the_thread_is_done_when_the_run_returns(ahead_run):
    assert not any(t.name.startswith("ahead: ") for t in threading.enumerate())


def test_a_failed_compile_ahead_is_a_warning_not_an_error():
    """The program is then compiled where it is called, which reports an error that persists."""
    ahead = Ahead(lambda: 1 / 0, "the evaluation")
    with pytest.warns(UserWarning, match=r"compiling the evaluation ahead failed \(ZeroDivisionError"):
        ahead.join()
