"""Shared fixtures: where the HIRO data lives, a simulated data set made at test time, and the CI
rule that a skip is a failure."""

from __future__ import annotations

import fcntl
import os
import sys
from collections.abc import Callable, Iterator, Sequence
from pathlib import Path

import pytest

REPO = Path(__file__).resolve().parents[1]
HIRO = Path(os.environ.get("RCBHT_HIRO_DATA", REPO.parent / "shared" / "data" / "hiro"))
IN_CI = os.environ.get("CI", "").lower() == "true"
REAL = "REAL_HIRO_ONE_SA_SUCCESS"

SIM_SUCCESS = "SIM_MUJOCO_SUCCESS"
"""Generated set of successful one-arm trials (four sub-tasks each), in the HIRO layout."""
SIM_FAILURE = "SIM_MUJOCO_FAILURE"
"""Generated set of one jammed trial (SIM_JAMMED), aborted after three sub-tasks: incomplete."""
SIM_JAMMED = "SIM-ONE-F-01-jamming"
SIM_TRIALS = 8
SIM_SEED = 10
SOURCES = (pytest.param("hiro", marks=pytest.mark.shared_data), "sim")
"""Trial sources of a property test (parametrize values): the REAL HIRO successes from ../shared
(marked shared_data) or the generated set."""

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


def made_once(
    factory: pytest.TempPathFactory, name: str, make: Callable[[Path], Path | None]
) -> Path | None:
    """`make(folder)` once a test run: pytest-xdist's workers of one run share the first
    worker's result through their common temporary folder (a lock file orders them)."""
    if "PYTEST_XDIST_WORKER" not in os.environ:
        return make(factory.mktemp(name))
    folder = factory.getbasetemp().parent / name
    with (folder.parent / f"{name}.lock").open("w") as lock:
        fcntl.flock(lock, fcntl.LOCK_EX)  # released when the file closes
        made = folder / ".made"
        if not made.exists():
            folder.mkdir(exist_ok=True)  # a worker whose make() failed may have left it
            result = make(folder)
            made.write_text("" if result is None else str(result))
        text = made.read_text()
    return Path(text) if text else None


@pytest.fixture(scope="session")
def sim_data(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """Root of a small data set made by the project's MuJoCo simulator (fixed seeds; 7-11 s once a
    session on 2 shared cores): SIM_SUCCESS and SIM_FAILURE in the HIRO layout. Property tests run
    on it everywhere, also without ../shared; nothing generated is kept in the repository."""
    root = made_once(tmp_path_factory, "sim_data", _write_sim_data)
    assert root is not None
    return root


def _write_sim_data(root: Path) -> Path:
    from rcbht_introspection.io.hiro import write_trial
    from rcbht_introspection.sim import load_sim_config, simulate_trial, write_dataset

    config = load_sim_config()
    write_dataset(root / SIM_SUCCESS, SIM_TRIALS, seed=SIM_SEED, config=config)
    jammed = simulate_trial(config, SIM_SEED * 1000 + 999, failure="jamming", name=SIM_JAMMED)
    assert len(jammed.state_times) == 3, "a jammed trial is aborted after three sub-tasks"
    write_trial(jammed, root / SIM_FAILURE / SIM_JAMMED)
    return root


@pytest.fixture(scope="session")
def bench_model(tmp_path_factory: pytest.TempPathFactory) -> Path | None:
    """The ROS benchmarks' classifier model, made once a session by bench/ros.py's bench_model
    (`rcbht train` default on REAL HIRO 1-40, live head included; ~30 s on 2 shared cores), or
    None without the shared data, as the benchmarks run then. The ROS benchmark, the soak and
    the end-to-end replay share it instead of training it each."""
    from ros_support import require_ros

    require_ros()  # bench/ros.py imports the replay harness, which imports rclpy
    from rcbht_introspection.bench.ros import bench_model as make

    return made_once(tmp_path_factory, "bench_model", make)


def dataset_root(request: pytest.FixtureRequest, dataset: str) -> Path:
    """Folder of a data set by name: a generated one (SIM_MUJOCO_*) or a shared HIRO one."""
    if dataset in (SIM_SUCCESS, SIM_FAILURE):
        return request.getfixturevalue("sim_data") / dataset
    return request.getfixturevalue("hiro_data") / dataset


def trial_folders(
    request: pytest.FixtureRequest, source: str, hiro: Sequence[str], sim: Sequence[int]
) -> list[Path]:
    """Trial folders of a property test: the named REAL HIRO successes (source "hiro") or the
    generated successful trials at the given indices (source "sim")."""
    if source == "hiro":
        return [dataset_root(request, REAL) / name for name in hiro]
    if source != "sim":
        raise ValueError(f"unknown trial source {source!r}")
    trials = generated_trials(request)
    return [trials[i] for i in sim]


def generated_trials(request: pytest.FixtureRequest) -> list[Path]:
    """All generated successful trial folders, in name order."""
    from rcbht_introspection.io.hiro import find_trials

    return find_trials([dataset_root(request, SIM_SUCCESS)])


def golden_or_engine(source: str) -> str:
    """Word source of a trial source: the original code's golden words for the HIRO trials, the
    batch engine's words for generated trials (which have no golden files)."""
    return "golden" if source == "hiro" else "engine"


@pytest.fixture(autouse=True)
def _release_ros_domains() -> Iterator[None]:
    """Give back the ROS domains a test leased (its node processes are stopped by then)."""
    yield
    supervision = sys.modules.get("rcbht_introspection.replay.supervision")
    if supervision is not None:
        supervision.release_domain()


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
