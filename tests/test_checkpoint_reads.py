"""agents.checkpoint._close_abandoned_reads: what a failed orbax restore leaves in its closed event loop is closed
quietly, and nothing else is touched."""

import asyncio
import gc
import logging
import os

from agents import checkpoint


def _coroutine_from(filename: str):
    """An `async def read(future)` compiled as if it were written in `filename`."""
    namespace = {}
    exec(compile("async def read(future):\n    return await future\n", filename, "exec"), namespace)
    return namespace["read"]


def _task_left_in_a_closed_loop(filename: str, fail: bool = False, gathered: bool = False):
    """A task of a coroutine from `filename` whose loop is closed: still waiting (the default), or failed; with
    `gathered`, the gather of it, failed, whose error nobody retrieved (what orbax leaves when a read fails)."""
    loop = asyncio.new_event_loop()
    awaited = loop.create_future()
    task = loop.create_task(_coroutine_from(filename)(awaited))
    outer = asyncio.gather(task) if gathered else None
    loop.run_until_complete(asyncio.sleep(0))  # the task starts and waits
    if fail:
        awaited.set_exception(OSError("damaged"))
        loop.run_until_complete(asyncio.sleep(0))
        loop.run_until_complete(asyncio.sleep(0))
    loop.close()
    return outer or task


def _orbax_file() -> str:
    return os.path.join(checkpoint._orbax_dir(), "checkpoint", "reading.py")


def test_an_orbax_read_left_waiting_is_closed():
    task = _task_left_in_a_closed_loop(_orbax_file())
    checkpoint._close_abandoned_reads()
    assert task.get_coro().cr_frame is None


def test_a_task_of_other_code_is_left_alone():
    task = _task_left_in_a_closed_loop("/elsewhere/reading.py")
    checkpoint._close_abandoned_reads()
    assert task.get_coro().cr_frame is not None
    task._log_destroy_pending = False  # the test's own cleanup
    task.get_coro().close()


def test_the_error_of_a_failed_orbax_gather_is_not_reported_again(caplog):
    gathered = _task_left_in_a_closed_loop(_orbax_file(), fail=True, gathered=True)
    assert gathered.done()
    checkpoint._close_abandoned_reads()
    del gathered
    with caplog.at_level(logging.ERROR, logger="asyncio"):
        gc.collect()
    assert "never retrieved" not in caplog.text


def test_the_error_of_another_failed_gather_is_still_reported(caplog):
    gathered = _task_left_in_a_closed_loop("/elsewhere/reading.py", fail=True, gathered=True)
    checkpoint._close_abandoned_reads()
    del gathered
    with caplog.at_level(logging.ERROR, logger="asyncio"):
        gc.collect()
    assert "never retrieved" in caplog.text
