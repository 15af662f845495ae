"""Encodings by name: a fresh one to fit, or a fitted one rebuilt from a model file's parameters."""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import replace
from typing import Any, Protocol

import numpy as np

from rcbht_introspection.errors import InputError
from rcbht_introspection.grammar import ENCODINGS
from rcbht_introspection.grammar.encoding.axes import AxisMemo
from rcbht_introspection.grammar.encoding.cache import SampleCache
from rcbht_introspection.grammar.encoding.compact import CompactEncoding
from rcbht_introspection.grammar.encoding.paper import PaperEncoding
from rcbht_introspection.grammar.encoding.wrench import WordsWrenchEncoding
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


AnyEncoding = PaperEncoding | CompactEncoding | WordsWrenchEncoding
"""Every encoding a model can hold."""


def with_cache(encoder: AnyEncoding, cache: SampleCache) -> AnyEncoding:
    """A copy of the fitted `encoder` that caches in `cache` (same parameters)."""
    if isinstance(encoder, WordsWrenchEncoding):
        return replace(encoder, words=replace(encoder.words, cache=cache))
    return replace(encoder, cache=cache)


def make_encoding(name: str, cache: SampleCache | None = None) -> AnyEncoding:
    """A fresh (unfitted) encoding by name; `cache` shares per-sample results with others."""
    if name == "words-wrench":
        words = CompactEncoding(values=False, cache=cache or SampleCache())
        return WordsWrenchEncoding(words=words)
    if name == "paper":
        return PaperEncoding() if cache is None else PaperEncoding(cache=cache)
    if name == "compact":
        return CompactEncoding() if cache is None else CompactEncoding(cache=cache)
    raise InputError(f"unknown encoding {name!r} (known: {', '.join(ENCODINGS)})")


def encoding_from_state(state: dict[str, Any]) -> AnyEncoding:
    """Rebuild a fitted encoding from its stored parameters; bad fields are one-line errors."""
    try:
        name = state["name"]
        if name == "words-wrench":
            return _words_wrench(state)
        if name == "paper":
            n = {str(k): int(v) for k, v in state["n"].items()}
            if set(n) != {lv.value for lv in LEVELS}:
                raise ValueError("n must name every level")
            return PaperEncoding(arms=tuple(map(str, state["arms"])), n=n)
        if name == "compact":
            return _compact(state)
    except (KeyError, TypeError, ValueError, AttributeError) as exc:
        raise InputError(f"bad encoding parameters: {exc}", field="encoding") from None
    raise InputError(f"unknown encoding {state.get('name')!r}", field="encoding.name")


def _compact(state: dict[str, Any]) -> CompactEncoding:
    """A fitted compact encoding from its parameters (ValueError, KeyError when malformed)."""
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


def _words_wrench(state: dict[str, Any]) -> WordsWrenchEncoding:
    """A fitted words + wrench encoding from its parameters."""
    words = _compact(state["words"])
    if words.values:
        raise ValueError("words-wrench word features must not hold absolute values")
    enc = WordsWrenchEncoding(
        words=words,
        arms=tuple(map(str, state["arms"])),
        lower=[float(x) for x in state["lower"]],
        scale=[float(x) for x in state["scale"]],
    )
    if (
        enc.arms != words.arms
        or len(enc.lower) != len(enc.scale)
        or (len(enc.lower) != enc.n_features - words.n_features)
    ):
        raise ValueError(
            "wrench arms, lower and scale do not match the word features (a model of another "
            "words-wrench version: train it again)"
        )
    return enc
