"""envs.cache.LRU: the bounded cache of traced functions."""

import threading

import pytest

from envs.cache import LRU


def test_the_least_recently_used_entry_goes_first():
    cache = LRU(2)
    cache.get("a", lambda: 1)
    cache.get("b", lambda: 2)
    cache.get("a", lambda: 10)  # a used again: b is now the oldest
    cache.get("c", lambda: 3)
    assert cache.values() == [1, 3]


def test_an_entry_is_made_once_while_cached():
    cache, made = LRU(4), []
    for _ in range(3):
        cache.get("a", lambda: made.append(1) or len(made))
    assert made == [1]


def test_a_cached_none_is_not_made_again():
    cache, made = LRU(4), []
    for _ in range(2):
        cache.get("a", lambda: made.append(1))  # append returns None, the entry
    assert made == [1]


def test_a_size_below_one_is_refused():
    with pytest.raises(ValueError, match="size=0"):
        LRU(0)


def test_make_may_use_the_cache():
    cache, results = LRU(4), []
    worker = threading.Thread(target=lambda: results.append(cache.get("a", lambda: cache.get("b", lambda: 2) + 1)))
    worker.start()
    worker.join(timeout=10)  # a make run under the lock would wait on it forever
    assert results == [3]


def test_the_entry_stored_first_is_kept():
    cache = LRU(4)
    first = cache.get("a", lambda: cache.get("a", lambda: "inner") and "outer")  # the inner make stores first
    assert first == "inner"
