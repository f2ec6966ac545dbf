"""A bounded, thread-safe cache of what tracing makes, the least recently used dropped first: MuJoCo's jitted step
per MJX model (envs/physics.py), the evaluation program per env shape (agents/sweep.py), the observation sizes per
env config (envs/arm.py)."""

from __future__ import annotations

import collections
import threading
from typing import Callable, Hashable

_ABSENT = object()


class LRU:
    """At most `size` entries; `get(key, make)` returns the entry of `key`, made by `make()` when absent. `make` runs
    outside the cache's lock (it may trace, or use the cache): two threads asking for one key at once may both make
    it, and the entry stored first is the one both get."""

    def __init__(self, size: int):
        if size < 1:
            raise ValueError(f"size={size}: allowed is at least 1.")
        self.size = size
        self._entries: collections.OrderedDict = collections.OrderedDict()
        self._lock = threading.Lock()  # the driver compiles programs in threads (agents.ahead) while others trace

    def get(self, key: Hashable, make: Callable):
        with self._lock:
            entry = self._entries.get(key, _ABSENT)
            if entry is not _ABSENT:
                self._entries.move_to_end(key)
                return entry
        made = make()
        with self._lock:
            entry = self._entries.setdefault(key, made)
            self._entries.move_to_end(key)
            while len(self._entries) > self.size:
                self._entries.popitem(last=False)
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
