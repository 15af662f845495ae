"""`make`'s set-up on a machine that lacks a build tool: one line naming it, before anything is
installed (README, "Set-up: two commands")."""

from __future__ import annotations

import shutil
import subprocess
from pathlib import Path

import pytest

REPO = Path(__file__).resolve().parents[1]


@pytest.mark.parametrize("missing", ["cmake", "cc"])
def test_setup_names_a_missing_build_tool_in_one_line(tmp_path: Path, missing: str) -> None:
    make = shutil.which("make")
    assert make is not None
    tools = tmp_path / "bin"
    tools.mkdir()
    for name in ("cmake", "cc"):
        found = shutil.which(name)
        if name != missing and found is not None:
            (tools / name).symlink_to(found)
    venv = tmp_path / "venv"
    done = subprocess.run(
        [make, "-C", str(REPO), f"VENV={venv}", f"{venv}/.deps-stamp"],
        env={"PATH": str(tools)},
        capture_output=True,
        text=True,
        timeout=60,
    )
    assert done.returncode != 0
    said = [line for line in done.stderr.splitlines() if line.startswith("make: ")]
    assert said[0].startswith(f"make: {missing} not found"), done.stderr
    assert not venv.exists()  # nothing was installed
