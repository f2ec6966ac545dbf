"""The final evaluation compiled in a thread while the run trains (`agents.driver.evaluates_ahead`, on by itself on an
accelerator): forced on here on the CPU, the evaluation at the end traces and compiles nothing, its numbers are those
of the same run evaluated without it, and the thread has ended whenever the run returns."""

import threading
import time

import jax
import pytest

from agents import driver, loop, presets
from agents.ahead import Ahead

RUN = dict(num_timesteps=10_240, seeds=1, log_every=5_120, tensorboard=False, progress=False)
"""Two chunks of the point-mass PPO preset."""


@pytest.fixture(scope="module")
def events():
    """JAX's compile events (tracing, lowering, compiling, or a persistent-cache hit) while this module runs."""
    seen = []

    def listener(name, seconds, **kwargs):
        if name.startswith(("/jax/core/compile/", "/jax/compilation_cache/")):
            seen.append(name)

    jax.monitoring.register_event_duration_secs_listener(listener)
    yield seen
    jax.monitoring.unregister_event_duration_listener(listener)


def train(events, path, monkeypatch, ahead: bool, eval_envs: int, **options):
    """(the run's result, the compile events during its final evaluation's call)."""
    monkeypatch.setattr(driver, "evaluates_ahead", lambda *args: ahead)
    during = []
    evaluate = driver.evaluate

    def counted(programs, state, config):
        before = len(events)
        out = evaluate(programs, state, config)
        during.extend(events[before:])
        return out

    monkeypatch.setattr(driver, "evaluate", counted)
    config = presets.make_config("point-mass-ppo", logdir=str(path), eval_envs=eval_envs, **RUN, **options)
    return driver.train(config), during


def ahead_threads() -> list:
    return [t for t in threading.enumerate() if t.name.startswith("ahead: ")]


def test_without_it_the_evaluation_compiles_when_called(events, tmp_path, monkeypatch):
    """The control: the count sees a first call compile (an evaluation size no other test builds)."""
    _, during = train(events, tmp_path / "plain", monkeypatch, ahead=False, eval_envs=23)
    assert len(during) > 0


@pytest.fixture(scope="module")
def ahead_run(events, tmp_path_factory):
    with pytest.MonkeyPatch.context() as monkeypatch:
        return train(events, tmp_path_factory.mktemp("ahead") / "run", monkeypatch, ahead=True, eval_envs=29)


def test_with_it_the_evaluation_compiles_nothing_when_called(ahead_run):
    _, during = ahead_run
    assert during == []


def test_with_it_the_evaluation_gives_the_same_numbers(ahead_run, events, tmp_path, monkeypatch):
    result, _ = ahead_run
    driver.build_programs.cache_clear()  # the same run built and compiled afresh, its evaluation on first use
    jax.clear_caches()
    plain, during = train(events, tmp_path / "plain", monkeypatch, ahead=False, eval_envs=29)
    assert len(during) > 0  # compiled anew, not the executable of the run above
    assert result.eval_metrics == plain.eval_metrics


def test_it_follows_the_runs_matmul_precision(events, tmp_path, monkeypatch):
    """The precision is a context of the run's thread: the compile's thread takes it over (else the evaluation
    would compile again at the end, at the run's precision)."""
    _, during = train(events, tmp_path / "highest", monkeypatch, ahead=True, eval_envs=31, matmul_precision="highest")
    assert during == []


def slow_compile(monkeypatch, seconds: float):
    """Programs.evaluation_ahead as a compile that takes `seconds` and compiles nothing."""
    monkeypatch.setattr(loop.Programs, "evaluation_ahead",
                        lambda self, learner_states: Ahead(lambda: time.sleep(seconds), "the evaluation"))


def test_the_thread_has_ended_when_the_run_returns(tmp_path, monkeypatch):
    slow_compile(monkeypatch, 1.5)
    monkeypatch.setattr(driver, "evaluates_ahead", lambda *args: True)
    driver.train(presets.make_config("point-mass-ppo", logdir=str(tmp_path / "r"), eval_envs=29, **RUN))
    assert ahead_threads() == []


def test_the_thread_has_ended_when_the_run_fails(tmp_path, monkeypatch):
    class Unjoined(Ahead):
        def join(self):  # the failure comes before the thread is waited for
            pass

    monkeypatch.setattr(loop.Programs, "evaluation_ahead",
                        lambda self, learner_states: Unjoined(lambda: time.sleep(1.5), "the evaluation"))
    monkeypatch.setattr(driver, "evaluates_ahead", lambda *args: True)
    monkeypatch.setattr(driver, "evaluate", lambda *args: (_ for _ in ()).throw(RuntimeError("the evaluation failed")))
    with pytest.raises(RuntimeError, match="the evaluation failed"):
        driver.train(presets.make_config("point-mass-ppo", logdir=str(tmp_path / "r"), eval_envs=29, **RUN))
    assert ahead_threads() == []


def test_a_failed_compile_ahead_is_a_warning_not_an_error():
    """The program is then compiled where it is called, which reports an error that persists."""
    ahead = Ahead(lambda: 1 / 0, "the evaluation")
    with pytest.warns(UserWarning, match=r"compiling the evaluation ahead failed \(ZeroDivisionError"):
        ahead.join()


@pytest.mark.parametrize("options, expected", [
    (dict(), True),  # the control: a plain run on a GPU compiles it ahead
    (dict(stop_after_steps=5_120), False), (dict(stop_after_seconds=100.0), False),
    (dict(compile_eval_ahead=False), False), (dict(eval_envs=0), False)])
def test_only_a_run_set_to_end_with_its_evaluation_compiles_it_ahead(options, expected, monkeypatch):
    monkeypatch.setattr(jax, "default_backend", lambda: "gpu")
    config = presets.make_config("point-mass-ppo", **{**RUN, **options})
    total = driver.total_updates(config)
    stop = -(-config.stop_after_steps // driver.env_steps_per_update(config)) if config.stop_after_steps else total
    assert driver.evaluates_ahead(config, stop, total) is expected
