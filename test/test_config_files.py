"""The one YAML loader (config_files.py): shipped files load as before, bad ones give one line
naming file, line and field."""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass, replace
from pathlib import Path
from typing import Any, Literal

import pytest
import yaml

from rcbht_introspection.config_files import (
    REPO_CONFIG_DIR,
    choices_text,
    from_mapping,
    load_config,
    read_yaml,
)
from rcbht_introspection.configure.params import (
    ClassifierConfig,
    PlannerConfig,
    SegmenterConfig,
    SimNodeConfig,
    VerifierConfig,
    load_node_config,
)
from rcbht_introspection.errors import InputError
from rcbht_introspection.learn.live import LiveAugmentConfig, load_live_config
from rcbht_introspection.learn.online import TeachConfig, load_teach_config
from rcbht_introspection.plan.recovery import ClassRecovery, RecoveryConfig, load_recovery_config
from rcbht_introspection.sim.config import SimConfig, load_sim_config
from rcbht_introspection.sim.peg_config import PegConfig, load_peg_config
from rcbht_introspection.taxonomy.config import TaxonomyConfig, load_taxonomy_config
from rcbht_introspection.taxonomy.stream import StreamConfig, load_stream_config
from rcbht_introspection.verify.config import VerifyConfig, load_verify_config

TAXONOMY = TaxonomyConfig()
CELL_PROGRAM = replace(
    SimConfig().controller,
    start_height=(0.034, 0.034),
    approach_speed=(0.0065, 0.0065),
    tilt=(0.17, 0.17),
    rotation_speed=(0.0375, 0.0375),
    rotation_force=(7.0, 7.0),
    insertion_force_rate=(14.0, 14.0),
    hold_force=(28.0, 28.0),
    hold_time=(6.0, 6.0),
    retract_speed=(0.0002, 0.0002),
    retract_lateral=(0.00015, 0.00015),
)
CELL_FIXTURE = replace(SimConfig().variation, offset_xy=0.0002, offset_z=0.0002, offset_yaw=0.003)


def cell_with_slips(xy: tuple[float, float], yaw: tuple[float, float]) -> SimConfig:
    """The cell (sim/cell.yaml) with other deviation sizes (m, rad)."""
    failures = replace(SimConfig().failures, deviation_xy=xy, deviation_yaw=yaw)
    return replace(SimConfig(), controller=CELL_PROGRAM, variation=CELL_FIXTURE, failures=failures)


SHIPPED: dict[str, list[tuple[Callable[[Path], Any], Any]]] = {
    "rcbht.yaml": [
        (lambda p: load_taxonomy_config("reference", p), replace(TAXONOMY, profile="reference")),
        (
            lambda p: load_taxonomy_config("head", p),
            replace(
                TAXONOMY, profile="head", adjustment_mating_guard=False, duration_gate_breaks=False
            ),
        ),
        (
            lambda p: load_taxonomy_config("error_charac", p),
            replace(
                TAXONOMY,
                profile="error_charac",
                primitive_cleanup=False,
                final_segment=False,
                adjustment_mating_guard=False,
            ),
        ),
    ],
    "stream.yaml": [
        (lambda p: load_stream_config("reference", p), StreamConfig()),
        (lambda p: load_stream_config("causal", p), StreamConfig(profile="causal")),
        (
            lambda p: load_stream_config("live", p),
            StreamConfig(profile="live", finality_bound_s=1.9),
        ),
    ],
    "sim/snap.yaml": [(load_sim_config, SimConfig())],
    "sim/deviation_b.yaml": [
        (
            load_sim_config,
            replace(
                SimConfig(),
                failures=replace(
                    SimConfig().failures, deviation_xy=(0.0025, 0.0032), deviation_yaw=(0.08, 0.1)
                ),
            ),
        )
    ],
    "sim/cell.yaml": [
        (load_sim_config, replace(SimConfig(), controller=CELL_PROGRAM, variation=CELL_FIXTURE))
    ],
    "sim/cell_deviation_a.yaml": [
        (load_sim_config, cell_with_slips((0.0015, 0.00205), (0.04, 0.06)))
    ],
    "sim/cell_deviation_b.yaml": [
        (load_sim_config, cell_with_slips((0.00205, 0.0025), (0.06, 0.08)))
    ],
    "sim/peg.yaml": [(load_peg_config, PegConfig())],
    "recovery/snap.yaml": [
        (
            lambda p: load_recovery_config(path=p),
            RecoveryConfig(
                classes={
                    "deviation": ClassRecovery(
                        "undo_direction", size={"x": 0.002, "y": 0.002, "yaw": 0.06}
                    ),
                    "misalignment": ClassRecovery(
                        "undo_direction",
                        size={"y": 0.0055},
                        candidates=({"y": 0.0055}, {"y": -0.0055}),
                    ),
                    "jamming": ClassRecovery(
                        "undo_direction",
                        size={"yaw": 0.16},
                        candidates=({"yaw": 0.16}, {"yaw": -0.16}),
                    ),
                    "missed_snap": ClassRecovery("try", candidates=({"z": -0.0055},)),
                    "slip": ClassRecovery(
                        "undo_direction", size={"x": 0.002, "y": 0.002, "yaw": 0.06}
                    ),
                    "collision": ClassRecovery("retry"),
                    "anomaly": ClassRecovery("retry"),
                }
            ),
        )
    ],
    "recovery/peg.yaml": [
        (
            lambda p: load_recovery_config(path=p),
            RecoveryConfig(
                search_step={"yaw": 0.05},
                classes={
                    "hole_yaw": ClassRecovery(
                        "undo_direction",
                        size={"yaw": 0.07},
                        candidates=({"yaw": 0.07}, {"yaw": -0.07}),
                    ),
                    "collision": ClassRecovery("retry"),
                    "anomaly": ClassRecovery("retry"),
                },
            ),
        )
    ],
    "live.yaml": [(load_live_config, LiveAugmentConfig())],
    "teach.yaml": [(load_teach_config, TeachConfig())],
    "verify.yaml": [(load_verify_config, VerifyConfig())],
    "segmenter.yaml": [(lambda p: load_node_config(SegmenterConfig, p), SegmenterConfig())],
    "classifier.yaml": [(lambda p: load_node_config(ClassifierConfig, p), ClassifierConfig())],
    "verifier.yaml": [(lambda p: load_node_config(VerifierConfig, p), VerifierConfig())],
    "sim_node.yaml": [(lambda p: load_node_config(SimNodeConfig, p), SimNodeConfig())],
    "planner.yaml": [(lambda p: load_node_config(PlannerConfig, p), PlannerConfig())],
}
"""Every shipped YAML file, how it is loaded and what it must load to (the values before the
loader was unified)."""


def test_every_shipped_yaml_file_is_covered() -> None:
    shipped = REPO_CONFIG_DIR.rglob("*.yaml")
    assert {p.relative_to(REPO_CONFIG_DIR).as_posix() for p in shipped} == set(SHIPPED)


@pytest.mark.parametrize("name", sorted(SHIPPED))
def test_shipped_files_load_to_the_same_objects(name: str) -> None:
    for load, expected in SHIPPED[name]:
        assert load(REPO_CONFIG_DIR / name) == expected


def _error(load: Callable[[Path], Any], path: Path, text: str) -> str:
    """The one-line message of loading `text` from `path`."""
    path.write_text(text)
    with pytest.raises(InputError) as info:
        load(path)
    message = str(info.value)
    assert "\n" not in message
    return message


def test_wrong_type(tmp_path: Path) -> None:
    f = tmp_path / "sim.yaml"
    text = "geometry:\n  clearance: 0.0004\nphysics:\n  timestep: 0.001\n  friction: abc\n"
    assert _error(load_sim_config, f, text) == (
        f"{f}, line 5, field physics.friction: expected a number, got 'abc'"
    )


def test_yaml_1_1_exponent_without_a_point_gets_a_hint(tmp_path: Path) -> None:
    f = tmp_path / "sim.yaml"
    assert _error(load_sim_config, f, "physics:\n  beam_armature: 1e-5\n") == (
        f"{f}, line 2, field physics.beam_armature: expected a number, got '1e-5' "
        "(YAML reads it as text; write 1.0e-5)"
    )


def test_unknown_key(tmp_path: Path) -> None:
    f = tmp_path / "sim.yaml"
    message = _error(load_sim_config, f, "physics:\n  timestep: 0.001\n  stifness: 3\n")
    assert message.startswith(f"{f}, line 3, field physics.stifness: unknown key (known: ")
    message = _error(load_sim_config, f, "physics: {}\nsensors: {}\n")
    assert message.startswith(f"{f}, line 2, field sensors: unknown key")


def test_missing_section_and_missing_required_key(tmp_path: Path) -> None:
    f = tmp_path / "live.yaml"
    assert _error(load_live_config, f, "# nothing\nlive:\n  step_s: 1.0\n") == (
        f"{f}, line 2, field live_augment: missing required key"
    )

    @dataclass(frozen=True)
    class Needs:
        name: str
        size: int = 1

    f.write_text("\n\nsize: 2\n")
    with pytest.raises(InputError) as info:
        load_config(Needs, f)
    assert str(info.value) == f"{f}, line 3, field name: missing required key"


def test_yaml_syntax_errors_name_the_line(tmp_path: Path) -> None:
    f = tmp_path / "sim.yaml"
    message = _error(load_sim_config, f, "physics:\n  friction: 0.3\n gravity: 9.81\n")
    assert message.startswith(f"{f}, line 3: not valid YAML: ")
    message = _error(load_sim_config, f, "physics:\n  contact_solref: [0.008,\n    1.0\n")
    assert message.startswith(f"{f}, line 4: not valid YAML: ")
    assert message.endswith("(while parsing a flow sequence from line 2)")
    assert _error(load_sim_config, f, "physics:\n  friction: 0.3\n  friction: 0.4\n") == (
        f"{f}, line 3: not valid YAML: duplicate key 'friction'"
    )


def test_tuples_lists_and_literals(tmp_path: Path) -> None:
    f = tmp_path / "sim.yaml"
    assert _error(load_sim_config, f, "physics:\n  contact_solref: [0.008, 1.0, 2.0]\n") == (
        f"{f}, line 2, field physics.contact_solref: expected 2 items, got 3"
    )
    assert _error(load_sim_config, f, "controller:\n  tilt:\n    - 0.1\n    - wide\n") == (
        f"{f}, line 4, field controller.tilt[1]: expected a number, got 'wide'"
    )
    s = tmp_path / "stream.yaml"
    text = "profiles:\n  reference:\n    nonfinite: hold\n"
    assert _error(lambda p: load_stream_config("reference", p), s, text) == (
        f"{s}, line 3, field profiles.reference.nonfinite: expected hold_last or drop, got 'hold'"
    )


def test_unknown_profile(tmp_path: Path) -> None:
    f = tmp_path / "stream.yaml"
    text = "# streams\nprofiles:\n  fast: {profile: causal}\n"
    assert _error(lambda p: load_stream_config("slow", p), f, text) == (
        f"{f}, line 2, field profiles: unknown stream profile 'slow' (known: fast)"
    )
    assert load_stream_config("fast", f) == StreamConfig(profile="causal")


def test_a_config_class_own_checks_carry_file_and_line(tmp_path: Path) -> None:
    f = tmp_path / "live.yaml"
    text = "live_augment:\n  step_s: 0.5\n  fractions:\n    - 0.5\n    - 1.5\n"
    assert _error(load_live_config, f, text) == (
        f"{f}, line 5, field live_augment.fractions[1]: must be in (0, 1], got 1.5"
    )
    t = tmp_path / "rcbht.yaml"
    text = "profiles:\n  reference:\n    window: 5\n    gradient_thresholds: [1.0, 2.0]\n"
    assert _error(lambda p: load_taxonomy_config("reference", p), t, text) == (
        f"{t}, line 4, field profiles.reference.gradient_thresholds: expected 8 values, got 2"
    )
    n = tmp_path / "seg.yaml"
    text = "segmenter_node:\n  ros__parameters:\n    arms: [R]\n    qos_depth: 0\n"
    assert _error(lambda p: load_node_config(SegmenterConfig, p), n, text) == (
        f"{n}, line 4, field segmenter_node.ros__parameters.qos_depth: must be >= 1, got 0"
    )


def test_unreadable_file(tmp_path: Path) -> None:
    missing = tmp_path / "none.yaml"
    with pytest.raises(InputError, match="cannot read"):
        read_yaml(missing)
    bad = tmp_path / "bin.yaml"
    bad.write_bytes(b"\xff\xfe\x00")
    with pytest.raises(InputError, match="not UTF-8"):
        read_yaml(bad)


def test_an_empty_file_is_the_defaults(tmp_path: Path) -> None:
    f = tmp_path / "sim.yaml"
    f.write_text("# all defaults\n")
    assert load_sim_config(f) == SimConfig()


def test_plain_mappings_without_lines_still_check_types() -> None:
    @dataclass(frozen=True)
    class Choice:
        mode: Literal["boundary", "window"] = "boundary"
        sizes: tuple[int, ...] = ()

    assert from_mapping(Choice, {"mode": "window", "sizes": [1, 2]}) == Choice("window", (1, 2))
    with pytest.raises(InputError) as info:
        from_mapping(Choice, {"mode": "psychic"})
    assert str(info.value) == "field mode: expected boundary or window, got 'psychic'"


def test_choices_text() -> None:
    assert choices_text(("a",)) == "a"
    assert choices_text(("a", "b")) == "a or b"
    assert choices_text(("a", "b", "c")) == "a, b or c"


def test_merge_keys_may_be_overridden_but_explicit_keys_not_repeated(tmp_path: Path) -> None:
    """YAML's `<<: *anchor` merges a mapping whose keys the explicit ones override (as PyYAML's
    safe_load reads it); a key written twice by hand is still an error."""
    from rcbht_introspection.config_files import read_yaml

    f = tmp_path / "anchors.yaml"
    f.write_text(
        "base: &base {window: 5, step: 1}\n"
        "other: &other {window: 6, gap: 2}\n"
        "one:\n  <<: *base\n  window: 7\n"
        "two:\n  <<: [*base, *other]\n  step: 3\n"
    )
    assert read_yaml(f) == yaml.safe_load(f.read_text())
    f.write_text("one:\n  <<: {window: 5}\n  window: 7\n  window: 8\n")
    with pytest.raises(InputError, match="line 4: not valid YAML: duplicate key 'window'"):
        read_yaml(f)
