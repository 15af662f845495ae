"""Streaming RCBHT for one arm: samples in, words out as soon as they are final.

`ArmStream.push(t, wrench6)` buffers the sample; every W samples (one window step of the
segmentation) the block's least-squares statistics are merged into the open segments of all six
axes at once. Closed segments become primitive words and flow through the same operator chain as
the batch engine (pipeline.AxisPipeline), which releases MCs and LLBs once no later sample can
change them. `finish()` is the end of the trial. With the `reference` profile the words equal the
batch output exactly; `causal` decides whole-trial quantities from the past only; `live` is causal
and releases every held row once its end is `finality_bound_s` old (ops.StreamContext.bound).

Whole-trial inputs and how the stream gets them (docs/streaming.md):
* moment-axis domain (4th largest/smallest sample of the trial): given in StreamConfig
  (`moment_domains`, e.g. from calibration), else moment-axis primitives wait until the running
  domain can no longer fall below the threshold, or until finish() (causal: running domain);
* rotation start (startIndex) and mating start (the 'a'-chain limit): `mark_boundary` events,
  marked when they happen (not later than the samples after them);
* step 3's largest amplitude: known once that pass stops (composition_ops.ContactAmplitudes).
Bad input never raises out of push(): each case has a counted policy (`counters`).
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Literal, Protocol

import numpy as np

from rcbht_introspection.config_files import config_path, load_profile
from rcbht_introspection.errors import InputError
from rcbht_introspection.taxonomy import StreamProfile
from rcbht_introspection.taxonomy.behaviors import behavior_word
from rcbht_introspection.taxonomy.compositions import composition_word
from rcbht_introspection.taxonomy.config import TaxonomyConfig, default_config
from rcbht_introspection.taxonomy.ops import Row, StreamContext
from rcbht_introspection.taxonomy.pipeline import AxisPipeline
from rcbht_introspection.taxonomy.primitives import (
    Segmenter,
    axis_thresholds,
    block_stats,
    block_stats_one,
    classify_gradient,
    primitive_word,
)
from rcbht_introspection.taxonomy.words import AXES, TrialWords, Word

STREAM_CONFIG_FILE = "stream.yaml"

NonfinitePolicy = Literal["hold_last", "drop"]
GapPolicy = Literal["count", "interpolate"]


class TrialLike(Protocol):
    """What the taxonomy reads of a trial (io.trial.Trial; taxonomy does not import io)."""

    @property
    def name(self) -> str: ...
    @property
    def time(self) -> np.ndarray: ...
    @property
    def wrench(self) -> dict[str, np.ndarray]: ...
    @property
    def state_times(self) -> tuple[float, ...]: ...
    @property
    def arms(self) -> tuple[str, ...]: ...


@dataclass(frozen=True)
class StreamConfig:
    """Streaming profile and the intake policies for bad samples (config/stream.yaml)."""

    profile: StreamProfile = "reference"
    moment_domains: dict[str, float] | None = None
    """Explicit moment-axis domains (calibration); None = wait for the trial's own (reference)."""
    nonfinite: NonfinitePolicy = "hold_last"
    """NaN/Inf components: repeat the axis's last finite value, or drop the sample."""
    max_gap_periods: float = 5.0
    """A time step longer than this many nominal periods is a gap."""
    gap_policy: GapPolicy = "count"
    """Gaps: count and go on (the fits are in seconds), or fill at the nominal period."""
    rate_window: int = 20
    """Intervals used to estimate the nominal sample period."""
    rate_tolerance: float = 0.1
    """A sustained period change beyond this fraction is a changed rate (counted, adopted)."""
    finality_bound_s: float | None = None
    """live profile: a word may be revised only until its end is this many seconds old, then it
    is final (decided as if no later row changed it). None = unbounded (reference, causal)."""


def _check(config: StreamConfig) -> None:
    """The bound belongs to the live profile, and the live profile needs one."""
    bound = config.finality_bound_s
    if config.profile == "live" and not (bound is not None and bound > 0):
        raise InputError(
            f"the live profile needs a bound > 0, got {bound}", field="finality_bound_s"
        )
    if config.profile != "live" and bound is not None:
        raise InputError(
            f"applies to the live profile only, not {config.profile!r}", field="finality_bound_s"
        )


def load_stream_config(profile: str = "reference", path: Path | str | None = None) -> StreamConfig:
    """One profile of config/stream.yaml (or of `path`)."""
    file = Path(path) if path is not None else config_path(STREAM_CONFIG_FILE)
    return load_profile(StreamConfig, file, profile, kind="stream", check=_check)


@dataclass
class IntakeCounters:
    """How often each bad-input policy fired."""

    nonfinite_samples: int = 0
    malformed_samples: int = 0
    duplicate_stamps: int = 0
    decreasing_stamps: int = 0
    gaps: int = 0
    interpolated_samples: int = 0
    rate_changes: int = 0
    late_boundaries: int = 0
    malformed_boundaries: int = 0


class DomainTracker:
    """Running 4th-largest / 4th-smallest sample of one axis (adjustAxes.m, without the future)."""

    def __init__(self, rank: int) -> None:
        self.rank = rank
        self.top: list[float] = []  # descending
        self.bottom: list[float] = []  # ascending

    def add(self, values: Sequence[float], vmax: float, vmin: float) -> bool:
        """Take in samples (with their max and min); True if the 4th largest/smallest changed."""
        rank = self.rank
        if len(self.top) == rank and vmax <= self.top[-1] and vmin >= self.bottom[-1]:
            return False  # the usual case: nothing new at either end
        changed = False
        if len(self.top) < rank or vmax > self.top[-1]:
            for v in values:
                if len(self.top) < rank or v > self.top[-1]:
                    self.top.append(v)
                    self.top.sort(reverse=True)
                    del self.top[rank:]
                    changed = True
        if len(self.bottom) < rank or vmin < self.bottom[-1]:
            for v in values:
                if len(self.bottom) < rank or v < self.bottom[-1]:
                    self.bottom.append(v)
                    self.bottom.sort()
                    del self.bottom[rank:]
                    changed = True
        return changed

    def domain(self, config: TaxonomyConfig) -> float:
        if not self.top:
            return 0.0
        return abs(config.domain_top_margin * self.top[-1]) + abs(
            config.domain_bottom_margin * self.bottom[-1]
        )

    def settled(self, config: TaxonomyConfig) -> bool:
        """True once no later sample can bring the domain below the threshold."""
        if len(self.top) < self.rank:
            return False
        return (
            self.top[-1] >= 0 >= self.bottom[-1] and self.domain(config) >= config.domain_threshold
        )


class ArmStream:
    """Streaming RCBHT of one arm (6 axes); see the module docstring."""

    def __init__(
        self,
        config: TaxonomyConfig | None = None,
        stream_config: StreamConfig | None = None,
        arm: str = "R",
    ) -> None:
        self.config = config or default_config()
        self.stream_config = stream_config or StreamConfig()
        self.arm = arm
        self.causal = self.stream_config.profile in ("causal", "live")
        bound = (
            self.stream_config.finality_bound_s if self.stream_config.profile == "live" else None
        )
        self.ctx = StreamContext(self.config, causal=self.causal, bound=bound)
        self.counters = IntakeCounters()
        self.segmenter = Segmenter(self.config)
        self.pipes = [AxisPipeline(self.ctx) for _ in AXES]
        self.window = self.config.window
        self._ts: list[float] = []
        self._ys: list[list[float]] = []
        self._last_t = -math.inf
        self._last_y: list[float] | None = None
        self._started = False
        self._finished = False
        self._seq = 0
        self._periods: list[float] = []
        self._period: float | None = None
        self._dt_lo = math.nan  # in-rate interval bounds once the period is known
        self._dt_hi = math.nan
        # moment-axis labels: thresholds per axis once known, else the segments wait
        given = self.stream_config.moment_domains or {}
        self._thresholds: list[tuple[float, ...] | None] = []
        self._trackers: dict[int, DomainTracker] = {}
        self._waiting: dict[int, list[list[float]]] = {}
        for a, axis in enumerate(AXES):
            if axis not in self.config.domain_axes:
                self._thresholds.append(axis_thresholds(axis, None, self.config))
            elif axis in given:
                self._thresholds.append(axis_thresholds(axis, given[axis], self.config))
            else:
                self._thresholds.append(None)
                self._trackers[a] = DomainTracker(self.config.domain_rank)
                self._waiting[a] = []

    # ------------------------------------------------------------------ words

    def _word(self, level: str, row: Row, axis: str) -> Word:
        self._seq += 1
        make = {"p": primitive_word, "c": composition_word, "b": behavior_word}[level]
        return make(row, axis, self.arm, self._seq)

    def _emit(self, a: int, mcs: list[Row], llbs: list[Row], out: list[Word]) -> None:
        axis = AXES[a]
        for m in mcs:
            out.append(self._word("c", m, axis))
        for b in llbs:
            out.append(self._word("b", b, axis))

    def _primitives(self, a: int, segs: list[list[float]], out: list[Word]) -> None:
        """Closed segments: label them (or let them wait for the domain) and run the pipeline."""
        thresholds = self._thresholds[a]
        if thresholds is None:
            if not self.causal:
                self._waiting[a].extend(segs)
                return
            thresholds = axis_thresholds(
                AXES[a], self._trackers[a].domain(self.config), self.config
            )
        axis = AXES[a]
        prims = [[*seg, classify_gradient(seg[5], thresholds)] for seg in segs]
        for prim in prims:
            out.append(self._word("p", prim, axis))
        mcs, llbs = self.pipes[a].push_rows(prims)
        self._emit(a, mcs, llbs, out)

    def _release_waiting(self, a: int, domain: float, out: list[Word]) -> None:
        self._thresholds[a] = axis_thresholds(AXES[a], domain, self.config)
        waiting = self._waiting.pop(a, [])
        self._trackers.pop(a, None)
        if waiting:
            self._primitives(a, waiting, out)

    def _closed(self, out: list[Word]) -> None:
        for a, segs in enumerate(self.segmenter.segments):
            if segs:
                self._primitives(a, list(segs), out)
                segs.clear()

    # ------------------------------------------------------------------ intake

    def _intake(self, t: float, values: list[float]) -> list[tuple[float, list[float]]]:
        """Apply the bad-input policies; the samples to feed (none, one, or gap fill)."""
        accepted = self._accepted(t, values)
        if accepted is None:
            return []
        samples = [(t, accepted)]
        if self._started:
            dt = t - self._last_t
            period = self._period
            if period is not None and dt > self.stream_config.max_gap_periods * period:
                self.counters.gaps += 1
                if self.stream_config.gap_policy == "interpolate":
                    samples = [*self._gap_fill(t, accepted, dt, period), (t, accepted)]
            else:
                self._track_rate(dt)
        return samples

    def _accepted(self, t: float, values: list[float]) -> list[float] | None:
        """The sample's values after the malformed, non-finite and stamp-order policies (a
        non-finite value may hold the last one); None when the sample is dropped (counted)."""
        c = self.counters
        if len(values) != len(AXES):
            c.malformed_samples += 1
            return None
        if not math.isfinite(t):
            c.malformed_samples += 1
            return None
        if not all(math.isfinite(v) for v in values):
            c.nonfinite_samples += 1
            if self.stream_config.nonfinite == "drop" or self._last_y is None:
                return None
            values = [
                v if math.isfinite(v) else last
                for v, last in zip(values, self._last_y, strict=True)
            ]
        if t == self._last_t:
            c.duplicate_stamps += 1
            return None
        if t < self._last_t:
            c.decreasing_stamps += 1
            return None
        return values

    def _gap_fill(
        self, t: float, values: list[float], dt: float, period: float
    ) -> list[tuple[float, list[float]]]:
        """Samples interpolated linearly from the last one at the nominal period across a gap
        of dt before (t, values), so the windows keep their length in time (counted)."""
        n = int(dt / period + 0.5) - 1
        last_y = self._last_y or values
        fill = []
        for k in range(1, n + 1):
            f = k / (n + 1)
            fill.append((self._last_t + k * dt / (n + 1),
                         [a + f * (b - a) for a, b in zip(last_y, values, strict=True)]))  # fmt: skip
        self.counters.interpolated_samples += len(fill)
        return fill

    def _track_rate(self, dt: float) -> None:
        """Nominal period from the first intervals; a sustained change is counted and adopted."""
        sc = self.stream_config
        if self._period is not None and abs(dt - self._period) <= sc.rate_tolerance * self._period:
            self._periods = []
            return
        self._periods.append(dt)
        if len(self._periods) >= sc.rate_window:
            if self._period is not None:
                self.counters.rate_changes += 1
            self._set_period(float(np.median(self._periods)))
            self._periods = []

    def _set_period(self, period: float) -> None:
        tol = self.stream_config.rate_tolerance
        self._period = period
        self._dt_lo = period * (1 - tol)
        self._dt_hi = min(period * (1 + tol), self.stream_config.max_gap_periods * period)

    # ------------------------------------------------------------------ samples

    def _feed(self, t: float, values: list[float], out: list[Word]) -> None:
        self._last_t = t
        self._last_y = values
        self.ctx.now = t
        if not self._started:
            self._started = True
            self.segmenter.start(t, values)
            for a, tr in self._trackers.items():
                tr.add((values[a],), values[a], values[a])
            return
        self._ts.append(t)
        self._ys.append(values)
        if len(self._ts) == self.window:
            self._block(out)

    def _block(self, out: list[Word], final: bool = False) -> None:
        self.ctx.now = self._ts[-1]
        self.segmenter.samples += len(self._ts)
        stats = block_stats_one(self._ts, self._ys)
        if self._trackers:
            bmax, bmin = stats[6], stats[7]
            for a in list(self._trackers):
                tr = self._trackers[a]
                lo, hi = bmin[a][0], bmax[a][0]
                if len(tr.top) == tr.rank and hi <= tr.top[-1] and lo >= tr.bottom[-1]:
                    continue  # nothing new at either end (checked before building the column)
                changed = tr.add([y[a] for y in self._ys], hi, lo)
                if changed and not self.causal and tr.settled(self.config):
                    self._release_waiting(a, tr.domain(self.config), out)
        self._ts = []
        self._ys = []
        self.segmenter.feed_blocks(stats, 1, final=final)
        self._closed(out)
        if self.ctx.waiting:
            self._poll(out)
        elif self.ctx.bound is not None:
            for a, pipe in enumerate(self.pipes):  # held rows reach the bound as time passes
                mcs, llbs = pipe.expire()
                self._emit(a, mcs, llbs, out)

    def _poll(self, out: list[Word]) -> None:
        for a, pipe in enumerate(self.pipes):
            mcs, llbs = pipe.poll()
            self._emit(a, mcs, llbs, out)

    def push(self, t: float, wrench6: Sequence[float]) -> list[Word]:
        """One sample in; the words that became final out. Never raises for bad input."""
        out: list[Word] = []
        try:
            t = float(t)
            values = list(map(float, wrench6))
        except (TypeError, ValueError):
            self.counters.malformed_samples += 1
            return out
        # the steady case: six finite values (an overflowing sum takes the checked path),
        # increasing at the nominal rate: no policy applies
        if (
            len(values) == 6
            and math.isfinite(sum(values))
            and self._dt_lo <= t - self._last_t <= self._dt_hi
            and not self._finished
        ):
            if self._periods:
                self._periods = []
            self._last_t = t
            self._last_y = values
            self._ts.append(t)
            self._ys.append(values)
            if len(self._ts) == self.window:
                self._block(out)
            return out
        if self._finished:
            self.counters.malformed_samples += 1
            return out
        for t_in, y_in in self._intake(t, values):
            self._feed(t_in, y_in, out)
        return out

    def push_many(self, t: np.ndarray, wrench: np.ndarray) -> list[Word]:
        """Many samples in; the same words as pushing them one by one, vectorised when clean."""
        t = np.asarray(t, dtype=np.float64)
        wrench = np.asarray(wrench, dtype=np.float64)
        n = len(t)
        clean = (
            wrench.ndim == 2
            and wrench.shape == (n, len(AXES))
            and bool(np.isfinite(t).all() and np.isfinite(wrench).all())
            and (n < 2 or bool((np.diff(t) > 0).all()))
            and (n == 0 or t[0] > self._last_t)
            and self.stream_config.gap_policy == "count"
            and not self._finished
        )
        out: list[Word] = []
        k = 0
        if clean:
            # sample by sample until the nominal period is known and the block is empty
            while k < n and (self._period is None or self._ts or not self._started):
                out.extend(self.push(t[k], wrench[k]))
                k += 1
            if k < n:
                out.extend(self._push_clean(t[k:], wrench[k:]))
                return out
        for j in range(k, n):
            out.extend(self.push(t[j], wrench[j]))
        return out

    def _push_clean(self, t: np.ndarray, wrench: np.ndarray) -> list[Word]:
        """Validated samples with an empty block: all whole blocks go to the segmenter at once."""
        out: list[Word] = []
        w, n, sc = self.window, len(t), self.stream_config
        period = self._period
        assert period is not None
        dts = np.diff(np.concatenate(([self._last_t], t)))
        steady = bool((np.abs(dts - period) <= sc.rate_tolerance * period).all())
        full = n // w
        if not steady or self.ctx.waiting or self.ctx.bound is not None or not full:
            # gaps, rate changes and the live profile's expiry (decided per window step) keep
            # their sample-by-sample bookkeeping
            for j in range(n):
                out.extend(self.push(t[j], wrench[j]))
            return out
        tb = t[: full * w].reshape(full, w)
        yb = wrench[: full * w].reshape(full, w, len(AXES))
        stats = block_stats(tb, yb)
        for a in list(self._trackers):
            tr = self._trackers[a]
            col = yb[:, :, a].ravel()
            tr.add(np.sort(col)[-tr.rank :].tolist(), float(col.max()), float(col.min()))
            tr.add(np.sort(col)[: tr.rank].tolist(), float(col.max()), float(col.min()))
        self.segmenter.samples += full * w
        self._periods = []
        self._last_t = float(tb[-1, -1])
        self._last_y = yb[-1, -1].tolist()
        self.ctx.now = self._last_t
        self.segmenter.feed_blocks(stats, full)
        self._closed(out)
        for a in list(self._trackers):
            tr = self._trackers[a]
            if not self.causal and tr.settled(self.config):
                self._release_waiting(a, tr.domain(self.config), out)
        if self.ctx.waiting:
            self._poll(out)
        for j in range(full * w, n):
            out.extend(self.push(t[j], wrench[j]))
        return out

    def mark_boundary(self, t: float, subtask: str = "") -> list[Word]:
        """A sub-task starts at time t (mark it before pushing samples after t)."""
        out: list[Word] = []
        try:
            t = float(t)
        except (TypeError, ValueError):
            t = math.nan
        if not math.isfinite(t):
            self.counters.malformed_boundaries += 1
            return out
        if t < self._last_t:
            self.counters.late_boundaries += 1
        self.ctx.boundaries.append(t)
        self._poll(out)
        return out

    def finish(self) -> list[Word]:
        """End of the trial: the last (partial) window, the domain, and every pending word."""
        out: list[Word] = []
        if self._finished:
            return out
        self._finished = True
        self.ctx.ended = True
        self.ctx.end_time = self._last_t if self._started else 0.0
        if self._started:
            if self._ts:
                self._block(out, final=True)
            else:
                self.segmenter.finish()
                self._closed(out)
        for a in list(self._waiting):
            tr = self._trackers.get(a)
            self._release_waiting(a, tr.domain(self.config) if tr else 0.0, out)
        for a, pipe in enumerate(self.pipes):
            mcs, llbs = pipe.finish()
            self._emit(a, mcs, llbs, out)
        return out

    def retained(self) -> dict[str, int]:
        """Size of the retained state (bounded-memory check)."""
        return {
            "pipeline_rows": sum(p.retained() for p in self.pipes),
            "waiting_segments": sum(len(v) for v in self._waiting.values()),
            "block_samples": len(self._ts),
            "open_segment_lists": sum(len(s) for s in self.segmenter.segments),
            "boundaries": len(self.ctx.boundaries),
        }


def label_trial_streamed(
    trial: TrialLike,
    config: TaxonomyConfig | None = None,
    stream_config: StreamConfig | None = None,
    many: bool = False,
) -> TrialWords:
    """Feed a Trial sample by sample (or with push_many) and collect the words in TrialWords.

    Sub-task boundaries are marked before the first sample after their time.
    """
    config = config or default_config()
    result = TrialWords(name=trial.name)
    for arm in trial.arms:
        stream = ArmStream(config, stream_config, arm)
        words: list[Word] = []
        marks = list(trial.state_times)
        time, wrench = trial.time, trial.wrench[arm]
        if many:
            k = 0
            for s in marks:
                j = int(np.searchsorted(time, s, side="right"))
                words += stream.push_many(time[k:j], wrench[k:j])
                words += stream.mark_boundary(s)
                k = j
            words += stream.push_many(time[k:], wrench[k:])
        else:
            m = 0
            for k in range(len(time)):
                tk = float(time[k])
                while m < len(marks) and marks[m] < tk:
                    words += stream.mark_boundary(marks[m])
                    m += 1
                words += stream.push(tk, wrench[k])
            for s in marks[m:]:
                words += stream.mark_boundary(s)
        words += stream.finish()
        per = result.words.setdefault(arm, {})
        for w in words:
            per.setdefault(w.level, {}).setdefault(w.axis, []).append(w)
    return result
