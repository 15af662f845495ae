"""docs/layout.md names every module of the package: a module added without a word there fails."""

from __future__ import annotations

import re
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
PACKAGE = ROOT / "rcbht_introspection"
LAYOUT = ROOT / "docs" / "layout.md"


def layout_sections(text: str) -> dict[str, str]:
    """The package tree of layout.md: folder ('' for the package's own top level, 'nodes', ...)
    -> its text (the folder's line and the indented lines under it)."""
    block = text.split("```\nrcbht_introspection/\n", 1)[1].split("```", 1)[0]
    sections: dict[str, str] = {}
    current = ""
    for line in block.splitlines():
        entry = re.match(r"  ([\w.]+)(/?)\s", line + " ")
        if entry and not line.startswith("   "):
            current = entry.group(1) if entry.group(2) else ""
        elif not line.startswith("  "):  # msg_defs/, config/, ...: outside the package
            current = "(outside)"
        sections[current] = sections.get(current, "") + line + "\n"
    return sections


MODULE_NAME = re.compile(r"(?<![\w/.-])(\w+)\.py\b")
"""A module as layout.md names it: its file name, `name.py` (a prose word is not a module)."""


def _modules(package: Path) -> dict[str, set[str]]:
    """Folder ('' for the package's top level) -> its modules' file stems, a subpackage's
    deeper modules counted in its top folder."""
    out: dict[str, set[str]] = {}
    for path in sorted(package.rglob("*.py")):
        rel = path.relative_to(package)
        if rel.name == "__init__.py" or "__pycache__" in rel.parts:
            continue
        folder = rel.parts[0] if len(rel.parts) > 1 else ""
        out.setdefault(folder, set()).add(rel.stem)
    return out


def layout_mismatches(text: str, package: Path = PACKAGE) -> tuple[list[str], list[str]]:
    """(modules of `package` their folder's section in `text` does not name as `name.py`,
    `name.py` the sections name that are no module of their folder)."""
    sections = layout_sections(text)
    modules = _modules(package)
    missing, unknown = [], []
    for folder, stems in sorted(modules.items()):
        named = set(MODULE_NAME.findall(sections.get(folder, "")))
        missing += [f"{folder}/{s}.py" if folder else f"{s}.py" for s in sorted(stems - named)]
    for folder, words in sorted(sections.items()):
        if folder == "(outside)":
            continue
        named = set(MODULE_NAME.findall(words))
        names = sorted(named - modules.get(folder, set()))
        unknown += [f"{folder}/{n}.py" if folder else f"{n}.py" for n in names]
    return missing, unknown


def test_layout_names_every_module_and_no_other() -> None:
    """Each module's file name appears in its folder's entry of docs/layout.md, and every file
    name there is a module of that folder."""
    assert layout_mismatches(LAYOUT.read_text()) == ([], [])


def test_the_layout_check_sees_a_missing_and_an_unknown_module() -> None:
    """A module named only as a prose word is missing; a file name without a module is unknown."""
    text = LAYOUT.read_text().replace("waiting.py", "waiting").replace("order.py", "orders.py")
    assert layout_mismatches(text) == (["waiting.py", "live/order.py"], ["live/orders.py"])
