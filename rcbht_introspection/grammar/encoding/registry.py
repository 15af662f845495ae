"""Encodings by name: a fresh one to fit, or a fitted one rebuilt from a model file's parameters."""

from __future__ import annotations

from collections.abc import Sequence
from typing import Any, Protocol

import numpy as np

from rcbht_introspection.errors import InputError
from rcbht_introspection.grammar import ENCODINGS
from rcbht_introspection.grammar.encoding.axes import AxisMemo
from rcbht_introspection.grammar.encoding.cache import SampleCache
from rcbht_introspection.grammar.encoding.compact import CompactEncoding
from rcbht_introspection.grammar.encoding.paper import PaperEncoding
from rcbht_introspection.grammar.split import SubtaskSample
from rcbht_introspection.taxonomy.words import LEVELS


class Encoding(Protocol):
    """A fitted map from samples to a fixed-length feature matrix."""

    name: str

    def fit(self, samples: Sequence[SubtaskSample]) -> Encoding: ...

    def transform(
        self, samples: Sequence[SubtaskSample], memo: AxisMemo | None = None
    ) -> np.ndarray: ...

    def to_state(self) -> dict[str, Any]: ...


def make_encoding(name: str, cache: SampleCache | None = None) -> PaperEncoding | CompactEncoding:
    """A fresh (unfitted) encoding by name; `cache` shares per-sample results with others."""
    if name == "paper":
        return PaperEncoding() if cache is None else PaperEncoding(cache=cache)
    if name == "compact":
        return CompactEncoding() if cache is None else CompactEncoding(cache=cache)
    raise InputError(f"unknown encoding {name!r} (known: {', '.join(ENCODINGS)})")


def encoding_from_state(state: dict[str, Any]) -> PaperEncoding | CompactEncoding:
    """Rebuild a fitted encoding from its stored parameters; bad fields are one-line errors."""
    try:
        name = state["name"]
        if name == "paper":
            n = {str(k): int(v) for k, v in state["n"].items()}
            if set(n) != {lv.value for lv in LEVELS}:
                raise ValueError("n must name every level")
            return PaperEncoding(arms=tuple(map(str, state["arms"])), n=n)
        if name == "compact":
            enc = CompactEncoding(
                values=bool(state["values"]),
                bigrams=bool(state["bigrams"]),
                k=None if state["k"] is None else int(state["k"]),
                arms=tuple(map(str, state["arms"])),
                feature_names=[str(x) for x in state["feature_names"]],
                lower=[float(x) for x in state["lower"]],
                scale=[float(x) for x in state["scale"]],
            )
            if not (len(enc.feature_names) == len(enc.lower) == len(enc.scale)):
                raise ValueError("feature_names, lower and scale differ in length")
            return enc
    except (KeyError, TypeError, ValueError, AttributeError) as exc:
        raise InputError(f"bad encoding parameters: {exc}", field="encoding") from None
    raise InputError(f"unknown encoding {state.get('name')!r}", field="encoding.name")
