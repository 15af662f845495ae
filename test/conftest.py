"""Shared fixtures: where the HIRO data lives, and the CI rule that a skip is a failure."""

from __future__ import annotations

import os
from pathlib import Path

import pytest

REPO = Path(__file__).resolve().parents[1]
HIRO = Path(os.environ.get("RCBHT_HIRO_DATA", REPO.parent / "shared" / "data" / "hiro"))
IN_CI = os.environ.get("CI", "").lower() == "true"

_skipped: list[str] = []


def require(condition: bool, why: str) -> None:
    """Skip locally when a prerequisite is missing, but fail in CI, where it must be present."""
    if condition:
        return
    if IN_CI:
        pytest.fail(f"prerequisite missing in CI: {why}", pytrace=False)
    pytest.skip(why)


@pytest.fixture(scope="session")
def hiro_data() -> Path:
    """Root of the shared HIRO data (../shared/data/hiro or $RCBHT_HIRO_DATA)."""
    require((HIRO / "REAL_HIRO_ONE_SA_SUCCESS").is_dir(), f"HIRO data not found at {HIRO}")
    return HIRO


def pytest_runtest_logreport(report: pytest.TestReport) -> None:
    if report.skipped:
        _skipped.append(report.nodeid)


def pytest_sessionfinish(session: pytest.Session, exitstatus: int) -> None:
    """In CI a skipped test is not a passed one: turn any skip into a failing exit status."""
    if IN_CI and _skipped and exitstatus == 0:
        print(f"\nCI: {len(_skipped)} test(s) skipped, which CI does not allow:")
        for nodeid in _skipped[:20]:
            print(f"  {nodeid}")
        session.exitstatus = pytest.ExitCode.TESTS_FAILED
