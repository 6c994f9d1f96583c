"""Values made from files, kept for the process while the files are unchanged.

The evaluator builds a fresh policy for every episode (and for every sub-env of a batch); what a policy reads
from its files (weights, statistics, a graph and its sidecar, all immutable) is made once and shared.
"""

from __future__ import annotations

import collections
from collections.abc import Callable, Hashable, Sequence
from pathlib import Path
from typing import Generic, TypeVar

T = TypeVar("T")


class FileCache(Generic[T]):
    """The last ``size`` values made from files, each kept while its files keep their size and modification time.

    Args:
        size: How many values to keep (the least recently used goes first).
    """

    def __init__(self, size: int = 8) -> None:
        self.size = size
        self._items: collections.OrderedDict[Hashable, T] = collections.OrderedDict()

    def get(self, files: Sequence[Path | None], extra: Hashable, make: Callable[[], T]) -> T:
        """The value for ``files`` (None or a missing file counts as absent) and ``extra``; ``make()`` on a miss.

        A ``make`` that raises caches nothing.
        """
        stamps = tuple(
            (str(f.resolve()), f.stat().st_mtime_ns, f.stat().st_size) if f is not None and f.is_file() else None
            for f in files
        )
        key = (stamps, extra)
        if key in self._items:
            self._items.move_to_end(key)
            return self._items[key]
        value = make()
        while len(self._items) >= self.size:
            self._items.popitem(last=False)
        self._items[key] = value
        return value
