"""The batch engine: a whole trial in, all three levels of words out (the reference oracle).

`label_trial` runs the primitive layer (the incremental Segmenter fed the whole trial at once),
gradient labels with the trial-wide moment-axis domain, clean-up, MC layer + filtering and LLB
layer + refinement for every arm and axis.
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np

from rcbht_introspection.taxonomy.config import TaxonomyConfig, default_config
from rcbht_introspection.taxonomy.primitives import axis_domain
from rcbht_introspection.taxonomy.stream import (
    ArmStream,
    StreamConfig,
    TrialLike,
    label_trial_streamed,
)
from rcbht_introspection.taxonomy.words import AXES, Level, TrialWords

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


def label_trial(
    trial: TrialLike,
    config: TaxonomyConfig | None = None,
    stream_config: StreamConfig | None = None,
) -> TrialWords:
    """Every arm of a Trial, all three levels (PRIMITIVE = the pre-clean-up Segments).

    A stream profile other than reference (causal, live) cannot know the future: its words are
    push_many between the sub-task starts, each marked when it happens, + finish().
    """
    config = config or default_config()
    if stream_config is not None and stream_config.profile != "reference":
        return label_trial_streamed(trial, config, stream_config, many=True)
    result = TrialWords(name=trial.name)
    for arm in trial.arms:
        label_arm(trial.time, trial.wrench[arm], trial.state_times, config, arm, result)
    return result
