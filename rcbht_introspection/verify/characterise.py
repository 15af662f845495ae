"""Failure characterisation: which failure class, and which way the part deviated (x, y, yaw).

Evidence is a span [onset, t] of ticks; its features are the mean, maximum and minimum of each
feature's signed envelope z over the span (how, and in which direction, the wrench left the
nominal envelope), the commanded sub-task at onset and the time into it. One of our Mondrian
forests (learn/mondrian.py) per head (class; one per deviation axis with '-', '0', '+'): on the
cell set it names the class of 0.90 of failures where a logistic regression on the same evidence
named 0.79 (docs/verification.md), and it is stored as plain arrays.

Heads given a contact weight (the class, x and y by default) also read where the part first
touched (`contact_geometry`), each through a second forest of its own: a Mondrian tree picks a
split feature in proportion to its range, so among a hundred envelope features a 2 mm shift of
the contact point would seldom be chosen. Evidence without a touch gives that forest no vote.

An axis given channels (`direction_channels`: x Fx and My, yaw Mz) has a second, narrow
direction head reading only those wrench axes, not what the controller did next on the others,
which changes with the slip's size; it takes over from the head reading all six as the evidence
grows (`direction_ramp_s`). When the class head names a deviation class, the direction heads'
signs weigh in on which one (`direction_weight`), through the training labels' sign table.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass, field
from typing import NamedTuple, Protocol

import numpy as np

from rcbht_introspection.learn.mondrian import MondrianForestClassifier
from rcbht_introspection.verify.config import WRENCH_AXES, VerifyConfig
from rcbht_introspection.verify.features import (
    PER_ARM,
    RATIO_MIN_FORCE,
    TrialFeatures,
    kind_columns,
)
from rcbht_introspection.verify.labels import DIRECTION_AXES, TrialLabel

Z_CLIP = 50.0
CONTACT_PER_ARM = 5
"""Contact geometry per arm: contact point y and x, yaw moment per pressing force (mm), lateral
force shares (%)."""
CONTACT_CLIP = 30.0
"""Contact features are clipped to +-this (mm, %): a lever over a near-zero force is noise."""
FAILURE = "class"
"""The failure-class head's name among the heads (the others: the deviation axes)."""


class EvidenceView(Protocol):
    """What evidence is read through: the sub-task envelope (the verifier), the whole-trial
    envelope (raw-wrench baseline) or the timing model (timing baseline)."""

    @property
    def phases(self) -> tuple[str, ...]: ...

    @property
    def reads_wrench(self) -> bool:
        """The view is of the wrench: contact geometry may be read beside it."""
        ...

    def z(self, tf: TrialFeatures) -> np.ndarray: ...


def _clipped(z: np.ndarray) -> np.ndarray:
    """Envelope z as the evidence reads it: NaN (a tick of no known sub-task) 0, clipped."""
    return np.clip(np.nan_to_num(z, nan=0.0), -Z_CLIP, Z_CLIP)


def _start_features(phase: str, phases: Sequence[str], elapsed: float) -> np.ndarray:
    """The evidence's first tick: its commanded sub-task one-hot over `phases`, time into it."""
    onehot = np.zeros(len(phases) + 1)
    if phase in phases:
        onehot[list(phases).index(phase)] = 1.0
    onehot[-1] = elapsed
    return onehot


def reference_tick(times: np.ndarray | Sequence[float], onset: float, config: VerifyConfig) -> int:
    """Index of the tick contact geometry is measured against: the last at or before onset -
    contact_reference_s, else the first."""
    at = onset - config.contact_reference_s + 1e-9
    return max(int(np.searchsorted(times, at, "right")) - 1, 0)


def evidence_features(
    tf: TrialFeatures, z: np.ndarray, phases: Sequence[str], onset: float, until: float
) -> np.ndarray:
    """Features of the evidence span [onset, until] of one trial (z: its envelope z per tick)."""
    sel = (tf.times >= onset - 1e-9) & (tf.times <= until + 1e-9)
    if not np.any(sel):
        sel = tf.times <= until + 1e-9
        sel[: max(int(np.sum(sel)) - 1, 0)] = False
    part = _clipped(z[sel])
    if len(part) == 0:
        part = np.zeros((1, z.shape[1]))
    first = int(np.argmax(sel)) if np.any(sel) else 0
    i = int(tf.phase_index[first])
    start = _start_features(tf.phases[i] if i >= 0 else "", phases, tf.elapsed[first])
    return np.concatenate([part.mean(axis=0), part.max(axis=0), part.min(axis=0), start])


def channel_columns(width: int, n_phases: int, channels: Sequence[str]) -> np.ndarray:
    """Columns of `evidence_features` (of `width`, over `n_phases` sub-tasks) that read the
    given wrench axes: their mean, maximum and minimum z of every kind and arm, and the start
    features."""
    n_z = (width - n_phases - 1) // 3
    keep = [WRENCH_AXES.index(c) for c in channels]
    z_cols = [c for c in range(n_z) if c % 6 in keep]
    blocks = [b * n_z + c for b in range(3) for c in z_cols]
    return np.array([*blocks, *range(3 * n_z, width)], dtype=int)


def sign_table(labels: Sequence[TrialLabel]) -> dict[tuple[str, ...], str]:
    """Direction signs (x, y, r) -> failure class, from labelled failures: a class whose every
    trial carries a deviation of the same signs, and whose signs no other class shares."""
    signs: dict[str, set[tuple[str, ...] | None]] = {}
    for lb in labels:
        d = lb.directions()
        signs.setdefault(lb.failure_class, set()).add(
            None if d is None else tuple(d[a] for a in DIRECTION_AXES)
        )
    owners: dict[tuple[str, ...], list[str]] = {}
    for cls, found in signs.items():
        if len(found) == 1 and (only := next(iter(found))) is not None:
            owners.setdefault(only, []).append(cls)
    return {key: names[0] for key, names in owners.items() if len(names) == 1}


class EvidenceTick(NamedTuple):
    """One tick as the live verifier keeps it for the characterisation."""

    time: float
    phase: str
    """The commanded sub-task ('' before the first)."""
    elapsed: float
    z: np.ndarray
    """Envelope z of every feature."""
    means: np.ndarray
    """Window mean wrench of every arm (`wrench_means`)."""


@dataclass(eq=False)
class RunningEvidence:
    """`evidence_features` and `contact_geometry` of [onset, now], kept one tick at a time (the
    live verifier): the same numbers as over the whole span, in constant time and memory per
    tick, however long the span grows."""

    phases: tuple[str, ...]
    onset: float
    config: VerifyConfig
    total: np.ndarray | None = None
    high: np.ndarray | None = None
    low: np.ndarray | None = None
    count: int = 0
    first: np.ndarray | None = None
    """The one-hot commanded sub-task and the time into it at the first tick."""
    contact_times: list[float] = field(default_factory=list)
    """The reference tick before onset and the ticks of the contact span after it ..."""
    contact_means: list[np.ndarray] = field(default_factory=list)
    """... and their mean wrench (the reference may repeat the first tick after onset: its
    change is then 0, below RATIO_MIN_FORCE, as in `contact_geometry`)."""

    @classmethod
    def begin(
        cls,
        phases: tuple[str, ...],
        onset: float,
        config: VerifyConfig,
        ticks: Sequence[EvidenceTick],
    ) -> RunningEvidence:
        """From the ticks kept so far: those at or after onset, measured against the last at or
        before onset - contact_reference_s (the first kept if none), as `contact_geometry`."""
        ev = cls(phases, onset, config)
        if not ticks:
            return ev
        ref = ticks[reference_tick([t.time for t in ticks], onset, config)]
        ev.contact_times, ev.contact_means = [ref.time], [ref.means]
        for t in ticks:
            if t.time >= onset - 1e-9:
                ev.add(t)
        return ev

    def add(self, tick: EvidenceTick) -> None:
        """The next tick (one before onset is not evidence)."""
        if tick.time < self.onset - 1e-9:
            return
        part = _clipped(tick.z)
        if self.total is None or self.high is None or self.low is None:
            self.total, self.high, self.low = part.copy(), part.copy(), part.copy()
            self.first = _start_features(tick.phase, self.phases, tick.elapsed)
        else:  # row by row, as numpy's mean over axis 0 of a 2-D array adds them
            self.total += part
            np.maximum(self.high, part, out=self.high)
            np.minimum(self.low, part, out=self.low)
        self.count += 1
        if tick.time <= self.onset + self.config.contact_s + 1e-9 and self.contact_times:
            self.contact_times.append(tick.time)
            self.contact_means.append(tick.means)

    def features(self) -> np.ndarray:
        """`evidence_features` of the span so far (at least one tick)."""
        if self.total is None or self.high is None or self.low is None or self.first is None:
            raise ValueError("no evidence yet: a tick at or after onset comes first")
        return np.concatenate([self.total / self.count, self.high, self.low, self.first])

    def geometry(self, until: float) -> np.ndarray | None:
        """`contact_geometry` of the span so far."""
        if not self.contact_times:
            return None
        return contact_geometry(
            np.array(self.contact_times),
            np.vstack(self.contact_means),
            self.onset,
            until,
            self.config,
        )


def wrench_means(tf: TrialFeatures) -> np.ndarray:
    """(ticks, 6 * arms) window mean wrench of every arm: what contact geometry is read from."""
    return tf.features[:, kind_columns(("mean",), tf.features.shape[1] // PER_ARM)]


def contact_geometry(
    times: np.ndarray, means: np.ndarray, onset: float, until: float, config: VerifyConfig
) -> np.ndarray | None:
    """Where and how the part touched, per arm: the change of the mean wrench since the tick
    `contact_reference_s` before onset (free motion: sensor bias and gripper load cancel),
    over the evidence's first `contact_s`, as the y and x where the contact force's line of
    action crosses the sensor's x-y plane (dMx/dFz, -dMy/dFz; the contact point, up to its
    height times the lateral force share), the yaw moment per pressing force (dMz/dFz), both
    in mm, and the lateral force shares (dFx/dFz, dFy/dFz) in %: each tick's clipped to
    +-CONTACT_CLIP, then averaged over the ticks whose |dFz| exceeds RATIO_MIN_FORCE (zeros
    for an arm without one). None when no arm touched: no contact, no geometry."""
    n_arms = means.shape[1] // 6
    if len(times) == 0:
        return None
    ref = reference_tick(times, onset, config)
    end = min(until, onset + config.contact_s)
    sel = (times >= onset - 1e-9) & (times <= end + 1e-9)
    out, touched = [], False
    for a in range(n_arms):
        d = means[sel, 6 * a : 6 * a + 6] - means[ref, 6 * a : 6 * a + 6]
        touching = np.abs(d[:, 2]) > RATIO_MIN_FORCE
        if not np.any(touching):
            out.append(np.zeros(CONTACT_PER_ARM))
            continue
        touched = True
        d = d[touching]
        fz = d[:, 2]
        geometry = np.column_stack(
            [
                d[:, 3] / fz * 1e3,
                -d[:, 4] / fz * 1e3,
                d[:, 5] / fz * 1e3,
                d[:, 0] / fz * 100,
                d[:, 1] / fz * 100,
            ]
        )
        out.append(np.clip(geometry, -CONTACT_CLIP, CONTACT_CLIP).mean(axis=0))
    return np.concatenate(out) if touched else None


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

    def proba_over(self, classes: Sequence[str], X: np.ndarray) -> np.ndarray:
        """Probabilities of one row over `classes` (a superset of this head's: 0 for the others)."""
        p = dict(zip(self.classes, self.predict_proba(X)[0], strict=True))
        return np.array([p.get(c, 0.0) for c in classes])


@dataclass
class Characteriser:
    """The failure-class head and, when deviation labels exist, one direction head per axis.
    `contact`: per head with a contact weight, a forest on contact geometry, trained on the
    evidence where the part touched, whose probabilities weigh `config.contact_weights[head]`
    in that head's when the evidence touched (empty: a view without wrench, or no weights).
    `narrow`: per axis with channels, a direction head reading only its `columns` of the
    evidence (`channel_columns` of `config.direction_channels`, derived, not stored); `signs`:
    the training labels' direction signs -> class (`sign_table`)."""

    phases: tuple[str, ...]
    failure: ForestHead
    directions: dict[str, ForestHead]
    config: VerifyConfig
    contact: dict[str, ForestHead] = field(default_factory=dict)
    narrow: dict[str, ForestHead] = field(default_factory=dict)
    signs: dict[tuple[str, ...], str] = field(default_factory=dict)
    columns: dict[str, np.ndarray] = field(init=False, repr=False)

    def __post_init__(self) -> None:
        width = self.failure.forest.n_features_in_
        self.columns = {
            axis: channel_columns(width, len(self.phases), self.config.direction_channels[axis])
            for axis in self.narrow
        }

    @classmethod
    def fit(
        cls,
        failures: Sequence[tuple[TrialFeatures, TrialLabel, float]],
        view: EvidenceView,
        config: VerifyConfig,
        seed: int = 0,
    ) -> Characteriser:
        """Learn from labelled failures: (features, label, onset) per trial, evidence spans
        config.evidence_s after onset and the whole rest of the trial; contact forests only
        where the view reads the wrench (not the timing baseline's)."""
        phases = view.phases
        contact = view.reads_wrench and any(w > 0 for w in config.contact_weights.values())
        X, y, dirs = [], [], []
        C: list[np.ndarray | None] = []
        for tf, label, onset in failures:
            z = view.z(tf)
            means = wrench_means(tf) if contact else None
            for span in (*config.evidence_s, np.inf):
                until = min(onset + span, tf.end)
                X.append(evidence_features(tf, z, phases, onset, until))
                if means is not None:
                    C.append(contact_geometry(tf.times, means, onset, until, config))
                y.append(label.failure_class)
                dirs.append(label.directions())
        if not X:
            raise ValueError("no failure trials to learn failure classes from")
        targets: dict[str, tuple[list[int], list[str]]] = {FAILURE: (list(range(len(y))), y)}
        labelled = [i for i, d in enumerate(dirs) if d is not None]
        if labelled:
            for axis in DIRECTION_AXES:
                targets[axis] = (labelled, [dirs[i][axis] for i in labelled])  # type: ignore[index]
        trees = config.characteriser_trees
        Xa = np.vstack(X)
        columns = {
            axis: channel_columns(Xa.shape[1], len(phases), channels)
            for axis, channels in config.direction_channels.items()
            if view.reads_wrench and axis in targets
        }
        heads = {h: ForestHead.fit(Xa[rows], t, trees, seed) for h, (rows, t) in targets.items()}
        narrow = {
            h: ForestHead.fit(Xa[targets[h][0]][:, cols], targets[h][1], trees, seed)
            for h, cols in columns.items()
        }
        contact_forests: dict[str, ForestHead] = {}
        for h, (rows, t) in targets.items():
            touched = [
                (g, c) for i, c in zip(rows, t, strict=True) if C and (g := C[i]) is not None
            ]
            if config.contact_weights.get(h, 0.0) > 0 and len({c for _, c in touched}) > 1:
                G = np.vstack([g for g, _ in touched])
                contact_forests[h] = ForestHead.fit(G, [c for _, c in touched], trees, seed + 1)
        failure = heads.pop(FAILURE)
        signs = sign_table([label for _, label, _ in failures]) if heads else {}
        return cls(phases, failure, heads, config, contact_forests, narrow, signs)

    def predict(
        self, tf: TrialFeatures, z: np.ndarray, onset: float, until: float, means: np.ndarray
    ) -> tuple[str, dict[str, float], dict[str, str]]:
        """(class, class probabilities, direction per axis) from the evidence [onset, until];
        `means`: the ticks' mean wrench (`wrench_means`), read when there are contact forests."""
        x = evidence_features(tf, z, self.phases, onset, until)
        g = contact_geometry(tf.times, means, onset, until, self.config) if self.contact else None
        return self.predict_from(x, g, until - onset)

    def predict_from(
        self, x: np.ndarray, g: np.ndarray | None, span: float
    ) -> tuple[str, dict[str, float], dict[str, str]]:
        """(class, class probabilities, direction per axis) from evidence features `x`
        (`evidence_features`) of `span` seconds since onset and contact geometry `g` (None:
        nothing touched; a non-finite one, from overflowing wrench, is read as none)."""
        x = x[None, :]
        if g is not None and not np.all(np.isfinite(g)):
            g = None
        ramp = min(max(span, 0.0) / self.config.direction_ramp_s, 1.0)

        def proba(name: str, head: ForestHead) -> np.ndarray:
            p = head.predict_proba(x)[0]
            if name in self.narrow:
                narrow = self.narrow[name].proba_over(head.classes, x[:, self.columns[name]])
                p = (1 - ramp) * p + ramp * narrow
            if g is not None and name in self.contact:
                w = self.config.contact_weights[name]
                p = (1 - w) * p + w * self.contact[name].proba_over(head.classes, g[None, :])
            return p

        p = proba(FAILURE, self.failure)
        probs = {c: float(v) for c, v in zip(self.failure.classes, p, strict=True)}
        direction_p = {
            a: dict(zip(h.classes, proba(a, h), strict=True)) for a, h in self.directions.items()
        }
        dirs = {a: max(q, key=q.__getitem__) for a, q in direction_p.items()}
        named = self.failure.classes[int(np.argmax(p))]
        weight = self.config.direction_weight * ramp
        if weight > 0 and named in self.signs.values():

            def signs_p(key: tuple[str, ...]) -> float:
                """How much the direction heads believe in the signs `key` (x, y, r)."""
                found = [
                    direction_p.get(a, {}).get(s, 0.0)
                    for a, s in zip(DIRECTION_AXES, key, strict=True)
                ]
                return float(np.prod(found))

            score = {cls: probs[cls] * signs_p(key) ** weight for key, cls in self.signs.items()}
            best = max(score, key=score.__getitem__)
            # the best deviation takes the class head's vote for its pick: still the most probable
            probs[named], probs[best] = probs[best], probs[named]
            named = best
        return named, probs, dirs
