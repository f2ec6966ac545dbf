"""A bounded, thread-safe cache of traced functions, the least recently used dropped first: MuJoCo's jitted step
per MJX model (envs/physics.py) and the evaluation program per env shape (agents/sweep.py)."""

from __future__ import annotations

import collections
import threading
from typing import Callable, Hashable

_ABSENT = object()


class LRU:
    """At most `size` entries; `get(key, make)` returns the entry of `key`, made by `make()` when absent. `make` runs
    under the cache's lock: it should be cheap (wrapping a function in `jax.jit` is; tracing it is not) and must not
    use the same cache."""

    def __init__(self, size: int):
        if size < 1:
            raise ValueError(f"size={size}: allowed is at least 1.")
        self.size = size
        self._entries: collections.OrderedDict = collections.OrderedDict()
        self._lock = threading.Lock()  # the driver compiles its evaluation in a thread while training traces

    def get(self, key: Hashable, make: Callable):
        with self._lock:
            entry = self._entries.get(key, _ABSENT)
            if entry is _ABSENT:
                entry = self._entries[key] = make()
                while len(self._entries) > self.size:
                    self._entries.popitem(last=False)
            self._entries.move_to_end(key)
            return entry

    def values(self) -> list:
        """The entries, the least recently used first."""
        with self._lock:
            return list(self._entries.values())

    def __len__(self) -> int:
        with self._lock:
            return len(self._entries)

    def clear(self) -> None:
        with self._lock:
            self._entries.clear()
