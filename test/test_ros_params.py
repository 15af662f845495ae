"""Node parameters: the shipped YAML files equal the defaults; bad values are one-line errors."""

from __future__ import annotations

from pathlib import Path

import pytest

from rcbht_introspection.configure.params import (
    ClassifierConfig,
    SegmenterConfig,
    VerifierConfig,
    config_from_parameters,
    defaults,
    descriptions,
    load_node_config,
    word_topics,
)
from rcbht_introspection.errors import InputError


def test_shipped_files_equal_defaults() -> None:
    assert load_node_config(SegmenterConfig) == SegmenterConfig()
    assert load_node_config(ClassifierConfig) == ClassifierConfig()
    assert load_node_config(VerifierConfig) == VerifierConfig()


@pytest.mark.parametrize("cls", [SegmenterConfig, ClassifierConfig, VerifierConfig])
def test_every_parameter_is_described(cls: type) -> None:
    assert all(len(text) > 10 for text in descriptions(cls).values())
    assert set(defaults(cls)) == set(descriptions(cls))


@pytest.mark.parametrize(
    ("cls", "values", "field"),
    [
        (SegmenterConfig, {"arms": []}, "arms"),
        (SegmenterConfig, {"arms": ["L", "L"], "wrench_topics": ["/a", "/b"]}, "arms"),
        (SegmenterConfig, {"arms": ["L", "R"]}, "wrench_topics"),
        (SegmenterConfig, {"qos_depth": 0}, "qos_depth"),
        (SegmenterConfig, {"qos_reliability": "sometimes"}, "qos_reliability"),
        (SegmenterConfig, {"qos_depth": "ten"}, "qos_depth"),
        (SegmenterConfig, {"event_hold_s": -1.0}, "event_hold_s"),
        (SegmenterConfig, {"taxonomy_config_file": "/no/such.yaml"}, "taxonomy_config_file"),
        (SegmenterConfig, {"taxonomy_model_file": "/no/such.rcbht"}, "taxonomy_model_file"),
        (SegmenterConfig, {"wrench_topic": "/w"}, "wrench_topic"),
        (ClassifierConfig, {"mode": "psychic"}, "mode"),
        (ClassifierConfig, {"window_s": 0.0}, "window_s"),
        (ClassifierConfig, {"publish_rate_hz": -2.0}, "publish_rate_hz"),
        (ClassifierConfig, {"state.hold_s": -0.1}, "state.hold_s"),
        (ClassifierConfig, {"state.min_probability": 2.0}, "state.min_probability"),
        (ClassifierConfig, {"state_topic": ""}, "state_topic"),
        (ClassifierConfig, {"teach_history_s": -1.0}, "teach_history_s"),
        (ClassifierConfig, {"teach_config_file": "/no/such.yaml"}, "teach_config_file"),
        (ClassifierConfig, {"teach_topic": "not a topic"}, "teach_topic"),
        (VerifierConfig, {"arms": ["L", "R"]}, "wrench_topics"),
        (VerifierConfig, {"event_max_hold_s": 0.1}, "event_max_hold_s"),
        (VerifierConfig, {"task_file": "/no/such.yaml"}, "task_file"),
        (VerifierConfig, {"publish_rate_hz": -1.0}, "publish_rate_hz"),
        (VerifierConfig, {"health_topic": ""}, "health_topic"),
        (VerifierConfig, {"verdict_topic": "not a topic"}, "verdict_topic"),
    ],
)
def test_bad_values_name_the_parameter(cls: type, values: dict, field: str) -> None:
    with pytest.raises(InputError) as info:
        config_from_parameters(cls, {**defaults(cls), **values})
    assert info.value.field == field
    assert "\n" not in str(info.value)


def test_parameter_file_errors(tmp_path: Path) -> None:
    bad = tmp_path / "seg.yaml"
    bad.write_text("segmenter_node:\n  ros__parameters:\n    arms: [R\n")
    with pytest.raises(InputError, match="line"):
        load_node_config(SegmenterConfig, bad)
    bad.write_text("other_node:\n  ros__parameters: {}\n")
    with pytest.raises(InputError, match="segmenter_node"):
        load_node_config(SegmenterConfig, bad)
    good = tmp_path / "cls.yaml"
    good.write_text("/**:\n  ros__parameters:\n    mode: window\n    window_s: 1.5\n")
    cfg = load_node_config(ClassifierConfig, good)
    assert cfg.mode == "window" and cfg.window_s == 1.5


def test_word_topics_per_arm() -> None:
    one = word_topics("rcbht", ("R",))
    assert one[("R", "primitives")] == "rcbht/primitives"
    two = word_topics("rcbht", ("L", "R"))
    assert two[("L", "behaviors")] == "L/rcbht/behaviors"
    assert len(set(two.values())) == 6
