"""The core session each node runs, built from the node's parameters (no ROS).

The classifier's and the verifier's are imported where they are built: segmenter_node runs
no model and starts without scikit-learn (test_architecture).
"""

from __future__ import annotations

from typing import TYPE_CHECKING

from rcbht_introspection.configure.params import (
    ClassifierConfig,
    SegmenterConfig,
    VerifierConfig,
    segmenter_taxonomy,
    task_events,
)
from rcbht_introspection.live.segmenter import SegmenterSession, arm_stream_factory
from rcbht_introspection.taxonomy.config import TaxonomyConfig
from rcbht_introspection.taxonomy.stream import ArmStream

if TYPE_CHECKING:
    from rcbht_introspection.live.belief import SampleClassifier
    from rcbht_introspection.live.classifier import ClassifierSession
    from rcbht_introspection.live.teach import Teacher
    from rcbht_introspection.verify.model_file import VerifierModel
    from rcbht_introspection.verify.stream import VerifierStream


def segmenter_session(
    cfg: SegmenterConfig,
) -> tuple[SegmenterSession[ArmStream], TaxonomyConfig]:
    """segmenter_node's session (stream, task, intake) and the taxonomy profile it labels with."""
    ends, task = task_events(cfg)
    taxonomy = segmenter_taxonomy(cfg)
    factory = arm_stream_factory(
        stream_file=cfg.stream_config_file, stream_profile=cfg.stream_profile, taxonomy=taxonomy
    )
    session = SegmenterSession(
        cfg.arms,
        factory,
        ends,
        task.subtasks if task else None,
        hold_s=cfg.event_hold_s,
        max_hold_s=cfg.event_max_hold_s,
        intake=cfg.intake,
    )
    return session, taxonomy


def classifier_session(
    cfg: ClassifierConfig,
    model: SampleClassifier | None,
    counts: dict[str, int],
    teaching: Teacher | None,
) -> ClassifierSession:
    """classifier_node's session (mode, window, state rule, teaching)."""
    from rcbht_introspection.live.belief import BeliefTracker
    from rcbht_introspection.live.classifier import ClassifierSession
    from rcbht_introspection.live.state import StateFilter

    history = cfg.teach_history_s if cfg.teach_enabled else 0.0
    tracker = BeliefTracker(
        model, cfg.mode, cfg.window_s, end_phases=cfg.end_phases, history_s=history
    )
    return ClassifierSession(tracker, StateFilter(cfg.state), counts, teaching)


def verifier_stream(model: VerifierModel, cfg: VerifierConfig) -> VerifierStream:
    """verifier_node's stream (arms, task, event hold)."""
    from rcbht_introspection.verify.stream import VerifierStream

    ends, task = task_events(cfg)
    subtasks = task.subtasks if task else None
    return VerifierStream(model, cfg.arms, ends, subtasks, cfg.event_hold_s, cfg.event_max_hold_s)
