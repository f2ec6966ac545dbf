"""agents/program_store.py: a traced evaluation program kept on disk is loaded by a later evaluation instead of traced,
and gives the numbers of the program traced afresh (CPU: the pure-JAX point mass; an arm on the native backend,
whose host callback cannot be exported)."""

import numpy as np
import pytest

import envs
from agents import evaluation, program_store


def _evaluate(name: str, **overrides):
    """A fresh evaluation program (as a new process builds it) of the random baseline, 8 episodes."""
    evaluation._evaluator.cache_clear()
    config = envs.make_config(name, None, **overrides)
    result = evaluation.run(evaluation.baseline_policy("random"), name, config, num_envs=8)
    stored = evaluation._evaluator(name, config, None, 0, 0, 8, 10, False, None).evaluate
    return result, stored


@pytest.fixture
def store(tmp_path):
    program_store.use(str(tmp_path))
    yield tmp_path
    program_store.use(None)
    evaluation._evaluator.cache_clear()


@pytest.fixture
def unstored():
    program_store.use(None)
    result, _ = _evaluate("point-mass")
    evaluation._evaluator.cache_clear()
    return result


def test_the_first_evaluation_writes_its_program(store):
    _evaluate("point-mass")
    assert len(list(store.glob("*.bin"))) == 1


def test_the_first_evaluation_traces(store):
    _, stored = _evaluate("point-mass")
    assert stored.loaded == 0


def test_a_later_evaluation_loads_it(store):
    _evaluate("point-mass")
    _, stored = _evaluate("point-mass")
    assert stored.loaded == 1


def test_the_loaded_program_gives_the_traced_numbers(unstored, store):
    _evaluate("point-mass")
    loaded, _ = _evaluate("point-mass")
    np.testing.assert_array_equal(loaded.per_env["return"], unstored.per_env["return"])


def test_another_setting_is_another_program(store):
    _evaluate("point-mass")
    _evaluate("point-mass", episode_length=7)
    assert len(list(store.glob("*.bin"))) == 2


def test_an_edited_source_is_another_key(monkeypatch):
    before = program_store.key(("evaluation",), (np.zeros(3, np.float32),))
    monkeypatch.setattr(program_store, "source_digest", lambda: "edited")
    assert program_store.key(("evaluation",), (np.zeros(3, np.float32),)) != before


def test_other_argument_shapes_are_another_key():
    assert (program_store.key(("evaluation",), (np.zeros(3, np.float32),))
            != program_store.key(("evaluation",), (np.zeros(4, np.float32),)))


def test_a_damaged_program_is_traced_again_with_a_warning(unstored, store):
    _evaluate("point-mass")
    path, = store.glob("*.bin")
    path.write_bytes(b"damaged")
    with pytest.warns(UserWarning, match="could not be read"):
        again, _ = _evaluate("point-mass")
    np.testing.assert_array_equal(again.per_env["return"], unstored.per_env["return"])


def test_a_host_callback_program_is_marked_unexportable(store):
    _evaluate("ur5e-reach", episode_length=3, substeps=2, backend="mujoco")
    path, = store.glob("*.bin")
    assert path.read_bytes() == program_store.UNEXPORTABLE


def test_a_program_marked_unexportable_runs_traced(store):
    first, _ = _evaluate("ur5e-reach", episode_length=3, substeps=2, backend="mujoco")
    second, _ = _evaluate("ur5e-reach", episode_length=3, substeps=2, backend="mujoco")
    np.testing.assert_array_equal(second.per_env["distance"], first.per_env["distance"])


def test_nothing_is_written_when_off(tmp_path):
    program_store.use(None)
    _evaluate("point-mass")
    assert list(tmp_path.iterdir()) == []
