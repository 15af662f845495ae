"""The batch engine: a whole trial in, all three levels of words out (the reference oracle).

`label_trial` runs the primitive layer (the incremental Segmenter fed the whole trial at once),
gradient labels with the trial-wide moment-axis domain, clean-up, MC layer + filtering and LLB
layer + refinement for every arm and axis.
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np

from rcbht_introspection.taxonomy.behaviors import (
    B_AMP,
    B_AMP1,
    B_AMP2,
    B_AVG1,
    B_AVG2,
    B_LBL,
    B_MAG,
    B_MC1,
    B_MC2,
    B_RMS,
    B_RMS1,
    B_RMS2,
    B_T1E,
    B_T1S,
    B_T2E,
    B_T2S,
    B_TAVG,
    Behavior,
)
from rcbht_introspection.taxonomy.compositions import (
    AMP,
    AVGV,
    GL1,
    GL2,
    LBL,
    RMS,
    T1E,
    T1S,
    T2E,
    T2S,
    TAVG,
    Composition,
)
from rcbht_introspection.taxonomy.config import TaxonomyConfig, load_taxonomy_config
from rcbht_introspection.taxonomy.primitives import (
    Primitive,
    axis_domain,
)
from rcbht_introspection.taxonomy.words import (
    AXES,
    BEHAVIOR_LABELS,
    COMPOSITION_LABELS,
    PRIMITIVE_LABELS,
    Level,
    TrialWords,
    Word,
)

_DEFAULT: TaxonomyConfig | None = None


def default_config() -> TaxonomyConfig:
    """The `reference` profile from config/rcbht.yaml (loaded once)."""
    global _DEFAULT
    if _DEFAULT is None:
        _DEFAULT = load_taxonomy_config("reference")
    return _DEFAULT


# --------------------------------------------------------------------------- records -> words


def primitive_word(p: Primitive, axis: str, arm: str, seq: int = 0) -> Word:
    """A primitive record as a Word with the Segments keys."""
    return Word(
        axis=axis, level=Level.PRIMITIVE, label=PRIMITIVE_LABELS[p[6] - 1],
        start=p[3], end=p[4], arm=arm, seq=seq,
        features={"Average": p[0], "Max Val": p[1], "Min Val": p[2], "Start": p[3],
                  "Finish": p[4], "Gradient": p[5]},
    )  # fmt: skip


def composition_word(m: Composition, axis: str, arm: str, seq: int = 0) -> Word:
    """An MC record as a Word with the Composites keys."""
    return Word(
        axis=axis, level=Level.COMPOSITION, label=COMPOSITION_LABELS[m[LBL] - 1],
        start=m[T1S], end=m[T2E], arm=arm, seq=seq,
        sublabels=(PRIMITIVE_LABELS[m[GL1] - 1], PRIMITIVE_LABELS[m[GL2] - 1]),
        features={"Average Val": m[AVGV], "RMS Val": m[RMS], "Amplitude Val": m[AMP],
                  "t1Start": m[T1S], "t1End": m[T1E], "t2Start": m[T2S], "t2End": m[T2E],
                  "tAvgIndex": m[TAVG]},
    )  # fmt: skip


def behavior_word(b: Behavior, axis: str, arm: str, seq: int = 0) -> Word:
    """An LLB record as a Word with the llBehaviors keys (mc1/mc2 printed via the MC table)."""
    return Word(
        axis=axis, level=Level.BEHAVIOR, label=BEHAVIOR_LABELS[b[B_LBL] - 1],
        start=b[B_T1S], end=b[B_T2E], arm=arm, seq=seq,
        sublabels=(COMPOSITION_LABELS[b[B_MC1] - 1], COMPOSITION_LABELS[b[B_MC2] - 1]),
        features={"averageVal1": b[B_AVG1], "averageVal2": b[B_AVG2], "AVG_MAG_VAL": b[B_MAG],
                  "rmsVal1": b[B_RMS1], "rmsVal2": b[B_RMS2], "AVG_RMS_Val": b[B_RMS],
                  "amplitudeVal1": b[B_AMP1], "amplitudeVal2": b[B_AMP2], "AVG_AMP_VAL": b[B_AMP],
                  "t1Start": b[B_T1S], "t1End": b[B_T1E], "t2Start": b[B_T2S], "t2End": b[B_T2E],
                  "tAvgIndex": b[B_TAVG]},
    )  # fmt: skip


# --------------------------------------------------------------------------- layers


def label_arm(
    time: np.ndarray,
    wrench: np.ndarray,
    state_times: Sequence[float],
    config: TaxonomyConfig,
    arm: str = "R",
    out: TrialWords | None = None,
) -> TrialWords:
    """All words of one arm ((N,) time, (N, 6) wrench) added to `out`.

    The batch engine is the streaming engine fed the whole trial at once: every sub-task start
    and the trial's moment-axis domains are known up front, and push_many() hands the segmenter
    all window steps in one vectorised call. One implementation of every rule.
    """
    from rcbht_introspection.taxonomy.stream import ArmStream, StreamConfig

    out = out if out is not None else TrialWords(name="")
    wrench = np.asarray(wrench, dtype=np.float64)
    time = np.asarray(time, dtype=np.float64)
    domains = {
        axis: axis_domain(wrench[:, AXES.index(axis)], config)
        for axis in config.domain_axes
        if axis in AXES and len(time)
    }
    stream = ArmStream(config, StreamConfig(moment_domains=domains), arm)
    for t in state_times:
        stream.mark_boundary(t)
    words = stream.push_many(time, wrench) + stream.finish()
    per_arm = out.words.setdefault(arm, {})
    for level in (Level.PRIMITIVE, Level.COMPOSITION, Level.BEHAVIOR):
        per_level = per_arm.setdefault(level, {})
        for axis in AXES:
            per_level.setdefault(axis, [])
    for w in words:
        per_arm[w.level][w.axis].append(w)
    return out


def label_trial(trial, config: TaxonomyConfig | None = None) -> TrialWords:
    """Every arm of a Trial, all three levels (PRIMITIVE = the pre-clean-up Segments)."""
    config = config or default_config()
    result = TrialWords(name=trial.name)
    for arm in trial.arms:
        label_arm(trial.time, trial.wrench[arm], trial.state_times, config, arm, result)
    return result
