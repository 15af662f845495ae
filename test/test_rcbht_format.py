"""The original text format (golden files, and our own label output on a generated trial)
round-trips byte for byte through our reader and writer."""

from __future__ import annotations

from pathlib import Path

import pytest
from conftest import SIM_SUCCESS

from rcbht_introspection.errors import InputError
from rcbht_introspection.io.hiro import find_trials
from rcbht_introspection.io.rcbht_format import level_path, read_words, write_words
from rcbht_introspection.taxonomy.words import AXES, Level


@pytest.mark.shared_data
def test_golden_files_round_trip(hiro_data: Path, tmp_path: Path) -> None:
    trials = sorted((hiro_data / "REAL_HIRO_ONE_SA_SUCCESS").iterdir())[:3]
    for trial in trials:
        for level in Level:
            for axis in AXES:
                golden = level_path(trial / "golden", level, axis)
                words = read_words(golden, level, axis)
                assert all(w.label in level.labels or w.label == "const" for w in words)
                ours = level_path(tmp_path / trial.name, level, axis)
                write_words(ours, level, words)
                assert ours.read_text() == golden.read_text(), golden


def test_label_output_round_trips(sim_data: Path, tmp_path: Path) -> None:
    """The files `rcbht label` writes for a generated trial read back and rewrite identically."""
    from rcbht_introspection.cli import main

    folder = find_trials([sim_data / SIM_SUCCESS])[0]
    assert main(["label", str(folder), "--out", str(tmp_path / "label")]) == 0
    for level in Level:
        for axis in AXES:
            written = level_path(tmp_path / "label" / folder.name, level, axis)
            words = read_words(written, level, axis)
            assert words and all(w.label in level.labels or w.label == "const" for w in words)
            again = level_path(tmp_path / "again", level, axis)
            write_words(again, level, words)
            assert again.read_text() == written.read_text(), written


def test_malformed_record_names_file_and_line(tmp_path: Path) -> None:
    path = tmp_path / "Composites_Fx.txt"
    path.write_text("Iteration : 1\nLabel : k\nt1Start : 0.0\nbroken line\n")
    with pytest.raises(InputError) as info:
        read_words(path, Level.COMPOSITION, "Fx")
    assert "Composites_Fx.txt" in str(info.value) and "4" in str(info.value)


def test_non_numeric_field_is_named(tmp_path: Path) -> None:
    path = tmp_path / "Composites_Fx.txt"
    path.write_text("Iteration : 1\nLabel : k\nt1Start : abc\nt2End : 1.0\n")
    with pytest.raises(InputError) as info:
        read_words(path, Level.COMPOSITION, "Fx")
    assert "t1Start" in str(info.value)
