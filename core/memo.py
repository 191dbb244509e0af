"""The one per-process cache every stage keeps its in-memory results in.

A stage declares a namespace with a capacity (``MEMO.namespace("parametric-loops", 4)``)
and uses it as a mapping. **The eviction policy, the same for every namespace:** an entry
read (``ns[key]``, ``get``, ``setdefault`` of a present key) or written becomes the most
recent; a write that takes a namespace past its capacity evicts its least recently used
entry. Nothing else evicts: no time limit, no memory limit, no effect of one namespace on
another. One lock guards every namespace (Dask runs tasks in worker threads; the console
steps its loop in a thread of its own). ``MEMO.clear()`` empties all of them (tests, and a
process that wants its memory back). A pure function is remembered with the decorator
``@MEMO.memoize("name", capacity)``: its namespace is keyed by the call's arguments.

The on-disk build cache (compiled libraries, derivations; ``core/build_cache.py``) is
a different thing: shared by processes and checkouts, keyed by content hashes.
"""

from __future__ import annotations

import functools
import threading
from collections import OrderedDict
from collections.abc import Callable, Hashable, Iterator
from typing import Any, ParamSpec, TypeVar

_P = ParamSpec("_P")
_R = TypeVar("_R")

#: the value ``get``/``pop`` return for a missing key unless given another
_MISSING = object()


class Namespace:
    """One stage's entries: a mapping with least-recently-used eviction at ``capacity``.

    Parameters
    ----------
    name : str
        The namespace's name (in :meth:`ProcessCache.sizes` and errors).
    capacity : int
        Most entries kept (>= 1).
    lock : threading.RLock
        The process cache's lock.
    """

    def __init__(self, name: str, capacity: int, lock: threading.RLock) -> None:
        self.name, self.capacity = name, capacity
        self._lock = lock
        self._data: OrderedDict[Hashable, Any] = OrderedDict()

    def __getitem__(self, key: Hashable) -> Any:
        with self._lock:
            value = self._data[key]
            self._data.move_to_end(key)
            return value

    def __setitem__(self, key: Hashable, value: Any) -> None:
        with self._lock:
            self._data[key] = value
            self._data.move_to_end(key)
            while len(self._data) > self.capacity:
                self._data.popitem(last=False)

    def __delitem__(self, key: Hashable) -> None:
        with self._lock:
            del self._data[key]

    def __contains__(self, key: object) -> bool:
        with self._lock:
            return key in self._data

    def __len__(self) -> int:
        with self._lock:
            return len(self._data)

    def __iter__(self) -> Iterator[Hashable]:
        with self._lock:
            return iter(list(self._data))

    def get(self, key: Hashable, default: Any = None) -> Any:
        """The entry (made most recent), or ``default``.

        Parameters
        ----------
        key : hashable
        default : object
        """
        with self._lock:
            return self[key] if key in self._data else default

    def setdefault(self, key: Hashable, value: Any) -> Any:
        """The entry of ``key`` (made most recent), set to ``value`` first when missing.

        Parameters
        ----------
        key : hashable
        value : object
        """
        with self._lock:
            if key not in self._data:
                self[key] = value
            return self[key]

    def pop(self, key: Hashable, default: Any = _MISSING) -> Any:
        """Remove and return the entry (``default`` when missing, else KeyError).

        Parameters
        ----------
        key : hashable
        default : object, optional
        """
        with self._lock:
            if default is _MISSING:
                return self._data.pop(key)
            return self._data.pop(key, default)

    def clear(self) -> None:
        """Remove every entry of this namespace."""
        with self._lock:
            self._data.clear()


class ProcessCache:
    """The namespaces of one process (:data:`MEMO`); see the module docstring."""

    def __init__(self) -> None:
        self._lock = threading.RLock()
        self._spaces: dict[str, Namespace] = {}

    def namespace(self, name: str, capacity: int) -> Namespace:
        """The namespace ``name``, created on first declaration.

        Parameters
        ----------
        name : str
            Unique per stage concept (``"certificates"``, ``"parametric-loops"``, ...).
        capacity : int
            Most entries kept; a second declaration must give the same capacity.

        Raises
        ------
        ValueError
            A capacity below 1, or another capacity than the first declaration's.
        """
        if int(capacity) < 1:
            raise ValueError(f"memo namespace {name!r}: capacity {capacity} must be >= 1")
        with self._lock:
            ns = self._spaces.get(name)
            if ns is None:
                ns = self._spaces[name] = Namespace(name, int(capacity), self._lock)
            elif ns.capacity != int(capacity):
                raise ValueError(
                    f"memo namespace {name!r}: declared with capacity {ns.capacity}, not {capacity}"
                )
            return ns

    def memoize(self, name: str, capacity: int) -> Callable[[Callable[_P, _R]], Callable[_P, _R]]:
        """Decorator: remember a pure function's results in namespace ``name``.

        The key is the positional arguments and the sorted keyword arguments (all must be
        hashable). The lock is not held while the function runs: two threads asking for
        the same missing key may both compute it, and the later write wins (the values
        are equal, the function being pure). The wrapper's ``cache_clear()`` empties
        the namespace, ``namespace`` is the namespace itself.

        Parameters
        ----------
        name : str
            The namespace's name.
        capacity : int
            Most results kept.
        """
        ns = self.namespace(name, capacity)

        def decorate(fn: Callable[_P, _R]) -> Callable[_P, _R]:
            @functools.wraps(fn)
            def remembered(*args: _P.args, **kwargs: _P.kwargs) -> _R:
                key = (args, tuple(sorted(kwargs.items()))) if kwargs else args
                value = ns.get(key, _MISSING)
                if value is _MISSING:
                    value = fn(*args, **kwargs)
                    ns[key] = value
                return value

            remembered.cache_clear = ns.clear  # type: ignore[attr-defined]
            remembered.namespace = ns  # type: ignore[attr-defined]
            return remembered

        return decorate

    def clear(self) -> None:
        """Empty every namespace."""
        with self._lock:
            for ns in self._spaces.values():
                ns.clear()

    def sizes(self) -> dict[str, tuple[int, int]]:
        """``{name: (entries, capacity)}`` of every namespace."""
        with self._lock:
            return {n: (len(ns), ns.capacity) for n, ns in self._spaces.items()}


#: the process's cache
MEMO = ProcessCache()
