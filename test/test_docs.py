"""The docs hold together: ros-parameters.md's tables are the config dataclasses', links and module
paths resolve, pages and the README stay short, the README counts the nodes right, and config
comments hold no measured figures."""

from __future__ import annotations

import re
from pathlib import Path

import pytest
import yaml

from rcbht_introspection.configure.params import (
    ClassifierConfig,
    PlannerConfig,
    SegmenterConfig,
    SimNodeConfig,
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
        (SimNodeConfig, "### sim_node"),
        (PlannerConfig, "### planner_node"),
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


ROOT = DOCS.parents[1]
PAGE_LINES = 400
README_LINES = 200
LINE_CHARS = 300
NUMBER_WORDS = {"one": 1, "two": 2, "three": 3, "four": 4, "five": 5, "six": 6}
MEASURED_COMMENT = re.compile(
    r"\d\s*(?:%|ms\b|s\b)"  # a figure in percent, milliseconds or seconds
    r"|\b(?:measured|gave|accuracy|accuracies|took|median|p99)\b"  # a statement of a result
    r"|\bin (?:all )?\d+ (?:of \d+ )?(?:trials|runs)\b",  # "in all 21 trials": an observation
    re.IGNORECASE,
)


def test_every_docs_page_is_short_with_short_lines() -> None:
    """A page over 400 lines is split by topic; a line over 300 characters is wrapped."""
    too_long = []
    for page in sorted((ROOT / "docs").glob("*.md")):
        lines = page.read_text().splitlines()
        if len(lines) > PAGE_LINES:
            too_long.append(f"{page.name}: {len(lines)} lines")
        too_long += [
            f"{page.name}:{n}: {len(line)} characters"
            for n, line in enumerate(lines, 1)
            if len(line) > LINE_CHARS
        ]
    assert not too_long, too_long


def test_readme_is_at_most_200_lines() -> None:
    """The README is for users (what, install, quick start, links); reference detail is in docs/."""
    lines = (ROOT / "README.md").read_text().splitlines()
    assert len(lines) <= README_LINES, len(lines)


def test_readme_counts_the_node_executables_it_names() -> None:
    """Every "<number> nodes" of the README is the number of scripts/*_node, each of them named."""
    text = (ROOT / "README.md").read_text()
    nodes = sorted(path.name for path in (ROOT / "scripts").glob("*_node"))
    assert nodes, "scripts/ holds the node executables"
    claims = re.findall(r"\b(\w+) (?:managed ROS 2 )?nodes\b", text, flags=re.IGNORECASE)
    counts = [NUMBER_WORDS[word.lower()] for word in claims if word.lower() in NUMBER_WORDS]
    assert counts, "the README says how many nodes there are"
    assert all(count == len(nodes) for count in counts), (claims, nodes)
    assert "both nodes" not in text.lower(), "'both nodes' counts two"
    missing = [name for name in nodes if f"`{name}`" not in text]
    assert not missing, missing


def measured_comments(text: str) -> list[str]:
    """The YAML comment lines (or trailing comments) that state a measured figure."""
    found = []
    for line in text.splitlines():
        if "#" in line and MEASURED_COMMENT.search(line[line.index("#") :]):
            found.append(line.strip())
    return found


@pytest.mark.parametrize(
    "line",
    [
        "# measured 0.93 accuracy",
        "  step_s: 0.5   # every 0.5 s of each sub-task",
        "# HIRO's approach ended 7.06-7.08 s after the start in all 21 trials",
        "rate_tolerance: 0.1  # a 10 % change",
        "# the learner took 36-58 ms per copy",
        "# 20,000 nodes gave 0.725",
    ],
)
def test_the_measured_comment_check_catches_a_figure(line: str) -> None:
    assert measured_comments(line) == [line.strip()]


def test_the_measured_comment_check_leaves_settings_alone() -> None:
    text = (
        "step_s: 0.5  # a window every step_s seconds (#1 of the list)\n"
        "rate_hz: 100.0  # a 100 Hz stream in 0.01 N units\n"
        "label: 'a # in a value' \n"
    )
    assert measured_comments(text) == []


def test_config_comments_hold_no_measured_figures() -> None:
    """A config comment says what a setting does; measured results live in docs/results*.md."""
    found = []
    for path in sorted((ROOT / "config").rglob("*.yaml")):
        found += [f"{path.name}: {line}" for line in measured_comments(path.read_text())]
    assert not found, found
