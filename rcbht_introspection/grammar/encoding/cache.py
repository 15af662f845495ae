"""SampleCache: the per-sample memo of an encoding's intermediate results (offline use).

An encoding owns one (a fresh one by default); callers that fit many encodings on the same
samples, like the learning-curve protocol, hand them one shared cache. Running windows are
encoded with an AxisMemo instead and never enter a SampleCache.
"""

from __future__ import annotations

from collections.abc import Callable
from typing import Any, TypeVar, cast

from rcbht_introspection.grammar.split import SubtaskSample

V = TypeVar("V")
"""The type of one cached result."""


class SampleCache:
    """Per-sample memo of expensive intermediate results, keyed by object identity.

    Holds a reference to each sample so an id is never reused while cached. Bounded to `limit`
    results: the oldest samples go first, one at a time, so no call pays for freeing them all.
    """

    def __init__(self, limit: int = 20000) -> None:
        self.limit = limit
        self.entries: dict[int, tuple[SubtaskSample, dict[Any, Any]]] = {}
        self.size = 0

    def get(self, sample: SubtaskSample, key: Any, compute: Callable[[], V]) -> V:
        """The result `key` of `sample`: cached, or `compute()` stored under it."""
        hit = self.entries.get(id(sample))
        if hit is not None and hit[0] is sample and key in hit[1]:
            return cast(V, hit[1][key])  # stored by compute() under the same key
        value = compute()
        if hit is None or hit[0] is not sample:
            self.forget(sample)
            while self.entries and self.size >= self.limit:
                self.size -= len(self.entries.pop(next(iter(self.entries)))[1])
            hit = self.entries[id(sample)] = (sample, {})
        hit[1][key] = value
        self.size += 1
        return value

    def __setstate__(self, state: dict[str, Any]) -> None:
        """Unpickled (on a joblib worker, with the samples it holds): keyed by the samples' new
        identities, so the copy of a warm cache is warm."""
        self.__dict__.update(state)
        self.entries = {id(sample): (sample, results) for sample, results in self.entries.values()}

    def forget(self, sample: SubtaskSample) -> None:
        """Drop every result of `sample` (it will not be encoded again)."""
        hit = self.entries.pop(id(sample), None)
        if hit is not None:
            self.size -= len(hit[1])
