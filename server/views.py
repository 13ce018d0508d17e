"""Serialised views of finished experiments, kept because they no longer change (a response cache).

Filled by API threads, emptied for an experiment whenever one of its runs
changes; a lock makes both safe from any thread, and a view loaded before a
change is never stored after it (:meth:`FinishedViews.generation`).
"""

from __future__ import annotations

import threading
from typing import Optional

__all__ = ["FinishedViews"]


class FinishedViews:
    """experiment id → (owner id, JSON bytes of its public view), at most ``max_entries``."""

    def __init__(self, max_entries: int = 4096) -> None:
        self._views: dict[int, tuple[int, bytes]] = {}
        self._changes: dict[int, int] = {}
        self._lock = threading.Lock()
        self._max = max_entries

    def get(self, experiment_id: int) -> Optional[tuple[int, bytes]]:
        with self._lock:
            return self._views.get(experiment_id)

    def generation(self, experiment_id: int) -> int:
        """Take this before loading a view; hand it to :meth:`put`."""
        with self._lock:
            return self._changes.get(experiment_id, 0)

    def put(self, experiment_id: int, owner_id: int, body: bytes, generation: int) -> None:
        """Keep a view loaded at ``generation`` unless the experiment changed since."""
        with self._lock:
            if self._changes.get(experiment_id, 0) != generation:
                return
            if len(self._views) >= self._max:
                self._views.pop(next(iter(self._views)))
            self._views[experiment_id] = (owner_id, body)

    def forget(self, experiment_id: int) -> None:
        """The experiment changed."""
        with self._lock:
            self._views.pop(experiment_id, None)
            if len(self._changes) > 100 * self._max:
                self._changes.clear()
            self._changes[experiment_id] = self._changes.get(experiment_id, 0) + 1
