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


def missing_modules(text: str, package: Path = PACKAGE) -> list[str]:
    """Modules of `package` whose name the section of their folder in `text` does not name
    (a subpackage's modules anywhere below it count in the subpackage's section)."""
    sections = layout_sections(text)
    missing = []
    for path in sorted(package.rglob("*.py")):
        rel = path.relative_to(package)
        if rel.name == "__init__.py" or "__pycache__" in rel.parts:
            continue
        folder = rel.parts[0] if len(rel.parts) > 1 else ""
        words = sections.get(folder, "")
        if not re.search(rf"(?<![\w/.]){re.escape(rel.stem)}(\.py)?(?!\w)", words):
            missing.append(str(rel))
    return missing


def test_layout_names_every_module() -> None:
    """Each module's name appears in its folder's entry of docs/layout.md."""
    assert missing_modules(LAYOUT.read_text()) == []


def test_the_layout_check_sees_a_missing_module() -> None:
    """Removing a module's name from its folder's entry makes the check fail for it."""
    text = LAYOUT.read_text().replace("waiting.py", "waits.py")
    assert missing_modules(text) == ["waiting.py"]
