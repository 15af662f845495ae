"""docs/ros.md's parameter tables are the config dataclasses': a changed field fails here."""

from __future__ import annotations

import re
from pathlib import Path

import pytest
import yaml

from rcbht_introspection.nodes.params import (
    ClassifierConfig,
    SegmenterConfig,
    VerifierConfig,
    defaults,
    descriptions,
)

DOCS = Path(__file__).resolve().parents[1] / "docs" / "ros-parameters.md"
AUTOSTART = ("autostart", True, "configure and activate at start-up, without a manager")


def table_after(heading: str) -> dict[str, tuple[str, str]]:
    """parameter -> (default cell, description cell) of the first table below `heading`."""
    text = DOCS.read_text()
    rows = {}
    start = text.index(heading)
    for line in text[start:].splitlines()[1:]:
        if rows and not line.startswith("|"):
            break
        cells = [c.strip() for c in line.strip().strip("|").split("|")]
        match = re.fullmatch(r"`([\w.]+)`", cells[0]) if len(cells) == 3 else None
        if match:
            rows[match.group(1)] = (cells[1].strip("`"), cells[2])
    return rows


@pytest.mark.parametrize(
    ("cls", "heading"),
    [
        (SegmenterConfig, "### segmenter_node"),
        (ClassifierConfig, "### classifier_node"),
        (VerifierConfig, "### verifier_node"),
    ],
)
def test_parameter_tables_match_the_config_dataclasses(cls: type, heading: str) -> None:
    expected = {name: (default, descriptions(cls)[name]) for name, default in defaults(cls).items()}
    expected[AUTOSTART[0]] = (AUTOSTART[1], AUTOSTART[2])
    rows = table_after(heading)
    assert list(rows) == list(expected)  # every field, in the dataclass's order
    for name, (default, description) in expected.items():
        cell, text = rows[name]
        shown = "" if cell == '""' else yaml.safe_load(cell)
        assert shown == default, name
        assert text == description, name


def test_the_autostart_row_is_the_nodes_own_description() -> None:
    source = (DOCS.parents[1] / "rcbht_introspection" / "nodes" / "common.py").read_text()
    assert f'description="{AUTOSTART[2]}"' in source


def test_every_relative_link_of_readme_and_docs_resolves() -> None:
    """A moved or renamed page or module breaks the link here, not for a reader."""
    root = DOCS.parents[1]
    broken = []
    for page in [root / "README.md", *sorted((root / "docs").glob("*.md"))]:
        for target in re.findall(r"\]\(([^)#\s]+)(?:#[^)]*)?\)", page.read_text()):
            if "://" in target:
                continue
            if not (page.parent / target).exists():
                broken.append(f"{page.relative_to(root)}: {target}")
    assert not broken, broken


def test_every_module_path_named_in_readme_and_docs_exists() -> None:
    """A page naming `live/belief.py` or `test/test_x.py` must name a file that is there."""
    root = DOCS.parents[1]
    missing = []
    for page in [root / "README.md", *sorted((root / "docs").glob("*.md"))]:
        for path in re.findall(r"`([a-z_]+/[a-z_/]+\.py)`", page.read_text()):
            if not (root / "rcbht_introspection" / path).exists() and not (root / path).exists():
                missing.append(f"{page.relative_to(root)}: {path}")
    assert not missing, missing
