"""Failure characterisation: which failure class, and which way the part deviated (x, y, yaw).

Evidence is a span [onset, t] of ticks; its features are the mean, maximum and minimum of each
feature's signed envelope z over the span (how, and in which direction, the wrench left the
nominal envelope), the commanded sub-task at onset and the time into it. One of our Mondrian
forests (learn/mondrian.py) per head (class; one per deviation axis with '-', '0', '+'): on the
cell set it names the class of 0.90 of failures where a logistic regression on the same evidence
named 0.79 (docs/verification.md), and it is stored as plain arrays.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass
from typing import Protocol

import numpy as np

from rcbht_introspection.learn.mondrian import MondrianForestClassifier
from rcbht_introspection.verify.config import VerifyConfig
from rcbht_introspection.verify.features import TrialFeatures
from rcbht_introspection.verify.labels import DIRECTION_AXES, TrialLabel

Z_CLIP = 50.0


class EvidenceView(Protocol):
    """What evidence is read through: the sub-task envelope (the verifier), the whole-trial
    envelope (raw-wrench baseline) or the timing model (timing baseline)."""

    @property
    def phases(self) -> tuple[str, ...]: ...

    def z(self, tf: TrialFeatures) -> np.ndarray: ...


def evidence_features(
    tf: TrialFeatures, z: np.ndarray, phases: Sequence[str], onset: float, until: float
) -> np.ndarray:
    """Features of the evidence span [onset, until] of one trial (z: its envelope z per tick)."""
    sel = (tf.times >= onset - 1e-9) & (tf.times <= until + 1e-9)
    if not np.any(sel):
        sel = tf.times <= until + 1e-9
        sel[: max(int(np.sum(sel)) - 1, 0)] = False
    part = np.clip(np.nan_to_num(z[sel], nan=0.0), -Z_CLIP, Z_CLIP)
    if len(part) == 0:
        part = np.zeros((1, z.shape[1]))
    first = int(np.argmax(sel)) if np.any(sel) else 0
    i = int(tf.phase_index[first])
    onehot = np.zeros(len(phases))
    if i >= 0 and tf.phases[i] in phases:
        onehot[list(phases).index(tf.phases[i])] = 1.0
    return np.concatenate(
        [part.mean(axis=0), part.max(axis=0), part.min(axis=0), onehot, [tf.elapsed[first]]]
    )


@dataclass
class ForestHead:
    """Evidence features -> class probabilities: a Mondrian forest, which splits where the
    failures' evidence differs, one feature at a time, so a class that leaves the envelope on
    a few features is not averaged away among a hundred."""

    forest: MondrianForestClassifier

    @property
    def classes(self) -> tuple[str, ...]:
        return tuple(str(c) for c in self.forest.classes_)

    @classmethod
    def fit(cls, X: np.ndarray, y: Sequence[str], trees: int, seed: int = 0) -> ForestHead:
        return cls(MondrianForestClassifier(n_estimators=trees, random_state=seed).fit(X, list(y)))

    def predict_proba(self, X: np.ndarray) -> np.ndarray:
        return self.forest.predict_proba(X)

    def predict(self, X: np.ndarray) -> list[str]:
        return [str(c) for c in self.forest.predict(X)]


@dataclass
class Characteriser:
    """The failure-class head and, when deviation labels exist, one direction head per axis."""

    phases: tuple[str, ...]
    failure: ForestHead
    directions: dict[str, ForestHead]

    @classmethod
    def fit(
        cls,
        failures: Sequence[tuple[TrialFeatures, TrialLabel, float]],
        view: EvidenceView,
        config: VerifyConfig,
        seed: int = 0,
    ) -> Characteriser:
        """Learn from labelled failures: (features, label, onset) per trial, evidence spans
        config.evidence_s after onset and the whole rest of the trial."""
        phases = view.phases
        X, y, dirs = [], [], []
        for tf, label, onset in failures:
            z = view.z(tf)
            for span in (*config.evidence_s, np.inf):
                X.append(evidence_features(tf, z, phases, onset, min(onset + span, tf.end)))
                y.append(label.failure_class)
                dirs.append(label.directions())
        if not X:
            raise ValueError("no failure trials to learn failure classes from")
        Xa = np.vstack(X)
        heads = {}
        labelled = [i for i, d in enumerate(dirs) if d is not None]
        if labelled:
            for axis in DIRECTION_AXES:
                heads[axis] = ForestHead.fit(
                    Xa[labelled],
                    [dirs[i][axis] for i in labelled],  # type: ignore[index]
                    config.characteriser_trees,
                    seed,
                )
        return cls(phases, ForestHead.fit(Xa, y, config.characteriser_trees, seed), heads)

    def predict(
        self, tf: TrialFeatures, z: np.ndarray, onset: float, until: float
    ) -> tuple[str, dict[str, float], dict[str, str]]:
        """(class, class probabilities, direction per axis) from the evidence [onset, until]."""
        x = evidence_features(tf, z, self.phases, onset, until)[None, :]
        p = self.failure.predict_proba(x)[0]
        probs = {c: float(v) for c, v in zip(self.failure.classes, p, strict=True)}
        dirs = {a: h.predict(x)[0] for a, h in self.directions.items()}
        return self.failure.classes[int(np.argmax(p))], probs, dirs
