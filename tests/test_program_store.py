"""agents/program_store.py: a traced evaluation program kept on disk is loaded by a later evaluation instead of traced,
and gives the numbers of the program traced afresh (CPU: the pure-JAX point mass and an arm on MJX; an arm on the
native backend, whose host callback cannot be exported, is marked and traced in every process)."""

import numpy as np
import pytest

import envs
from agents import evaluation, program_store

ARM_MJX = dict(episode_length=2, substeps=1, backend="mjx")
ARM_NATIVE = dict(episode_length=3, substeps=2, backend="mujoco")


def _evaluate(name: str, **overrides):
    """The random baseline on 4 episodes through a fresh evaluation program, as a new process builds it; the result
    and the program's `Stored`."""
    evaluation._evaluator.cache_clear()
    config = envs.make_config(name, None, **overrides)
    result = evaluation.run(evaluation.baseline_policy("random"), name, config, num_envs=4)
    stored = evaluation._evaluator(name, config, None, 0, 0, 4, 10, False, None).evaluate
    assert stored.calls or program_store._folder is None  # the program that ran, not a rebuilt one
    return result, stored


def _same(a, b) -> None:
    assert sorted(a.per_env) == sorted(b.per_env)
    for name in a.per_env:
        np.testing.assert_array_equal(a.per_env[name], b.per_env[name], err_msg=name)


@pytest.fixture
def store(tmp_path):
    program_store.use(str(tmp_path))
    yield tmp_path
    program_store.use(None)
    evaluation._evaluator.cache_clear()


def _unstored(name: str, **overrides):
    program_store.use(None)
    result, _ = _evaluate(name, **overrides)
    evaluation._evaluator.cache_clear()
    return result


def _files(store) -> list:
    return sorted(store.rglob("*.bin"))


def test_the_first_evaluation_writes_its_program(store):
    _evaluate("point-mass")
    assert len(_files(store)) == 1


def test_the_first_evaluation_traces(store):
    _, stored = _evaluate("point-mass")
    assert stored.loaded == 0


def test_a_later_evaluation_loads_it(store):
    _evaluate("point-mass")
    _, stored = _evaluate("point-mass")
    assert stored.loaded == 1


def test_the_loaded_program_gives_the_traced_numbers(tmp_path):
    unstored = _unstored("point-mass")
    program_store.use(str(tmp_path))
    try:
        _evaluate("point-mass")
        loaded, _ = _evaluate("point-mass")
    finally:
        program_store.use(None)
    _same(loaded, unstored)


def test_a_loaded_mjx_arm_program_gives_the_traced_numbers(tmp_path):
    unstored = _unstored("ur5e-reach", **ARM_MJX)
    program_store.use(str(tmp_path))
    try:
        _evaluate("ur5e-reach", **ARM_MJX)
        loaded, stored = _evaluate("ur5e-reach", **ARM_MJX)
    finally:
        program_store.use(None)
    assert stored.loaded == 1
    _same(loaded, unstored)


def test_another_setting_is_another_program(store):
    _evaluate("point-mass")
    _evaluate("point-mass", episode_length=7)
    assert len(_files(store)) == 2


def test_an_edited_source_is_another_key():
    args = (np.zeros(3, np.float32),)
    assert program_store.key(("evaluation",), args, "a") != program_store.key(("evaluation",), args, "b")


def test_other_argument_shapes_are_another_key():
    assert (program_store.key(("evaluation",), (np.zeros(3, np.float32),), "a")
            != program_store.key(("evaluation",), (np.zeros(4, np.float32),), "a"))


def test_a_damaged_program_is_traced_again_with_a_warning(tmp_path):
    unstored = _unstored("point-mass")
    program_store.use(str(tmp_path))
    try:
        _evaluate("point-mass")
        path, = _files(tmp_path)
        path.write_bytes(path.read_bytes()[:-7] + b"damaged")
        with pytest.warns(UserWarning, match="checksum mismatch"):
            again, stored = _evaluate("point-mass")
    finally:
        program_store.use(None)
    assert stored.loaded == 0
    _same(again, unstored)


@pytest.fixture(scope="module")
def native(tmp_path_factory):
    """An arm on the native backend evaluated twice with the store (each evaluation compiles: JAX's cache keeps no
    program with a host callback)."""
    folder = tmp_path_factory.mktemp("native")
    program_store.use(str(folder))
    try:
        with pytest.warns(UserWarning, match="traced in every process") as warned:
            first, _ = _evaluate("ur5e-reach", **ARM_NATIVE)
        marked, stored = _evaluate("ur5e-reach", **ARM_NATIVE)
    finally:
        program_store.use(None)
        evaluation._evaluator.cache_clear()
    return {"first": first, "warned": len(warned), "files": _files(folder), "marked": marked, "stored": stored}


def test_a_host_callback_program_is_marked_unexportable(native):
    assert [path.read_bytes() for path in native["files"]] == [program_store.UNEXPORTABLE]


def test_a_program_marked_unexportable_is_not_loaded(native):
    assert native["stored"].loaded == 0


def test_a_program_marked_unexportable_gives_the_numbers_of_the_first(native):
    _same(native["marked"], native["first"])


def test_nothing_is_written_once_turned_off(tmp_path):
    program_store.use(str(tmp_path))
    program_store.use(None)
    _evaluate("point-mass")
    assert _files(tmp_path) == []


def test_turning_it_on_deletes_other_code_versions_programs(tmp_path):
    old = tmp_path / ("0" * 16)
    old.mkdir()
    (old / "x.bin").write_bytes(b"old")
    program_store.use(str(tmp_path))
    program_store.use(None)
    assert not old.exists()
