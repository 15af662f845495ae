"""Every offline command of many inputs on joblib workers: `--jobs 1` against `--jobs 2`, the same
input, the same machine, one after the other.

Each scenario runs the command as a user does (its own interpreter) with `--jobs 1` and
`--jobs 2`, alternating, `RCBHT_BENCH_FLEET_REPEATS` times each (default 3), and reports every
wall time, the median of each, the speed-up of the medians and whether every run's output is
the first run's (files byte for byte; JSON without what names its own output path and, for
evaluate, without the measured fit and prediction times). Input: the shared data ($RCBHT_SHARED_DATA or ../shared/data beside the repository) for
verify-eval (the OpenHRP deviation failures with SIM_HIRO_ONE_SA_SUCCESS, 5 folds with the
anchors' methods), evaluate, label and calibrate (REAL_HIRO_ONE_SA_SUCCESS; evaluate with 5
permutations) and bag import and audit (the 19 Baxter bags, imported once for the audit); sim
makes its own 40 trials. A scenario whose data is missing reports itself skipped.
"""

from __future__ import annotations

import json
import os
import shutil
import statistics
import subprocess
import sys
import tempfile
import time
from collections.abc import Callable
from pathlib import Path
from typing import Any

REPO = Path(__file__).resolve().parents[2]
SHARED = Path(os.environ.get("RCBHT_SHARED_DATA", REPO.parent / "shared" / "data"))
JOBS = (1, 2)
REPEATS = int(os.environ.get("RCBHT_BENCH_FLEET_REPEATS", "3"))
"""Runs per job count: one run's speed-up moves by 0.2-0.3 on a shared 2-core VM."""
REAL = SHARED / "hiro" / "REAL_HIRO_ONE_SA_SUCCESS"
BAXTER = SHARED / "baxter_pick_and_place"
BAXTER_IMPORT = (
    "--wrench", "/tag_multimodal.wrench_stamped", "--phase", "/tag_multimodal.tag",
    "--phase-map", "0=-,1=approach,2=grasp,5=lift,3=transport,4=place",
)  # fmt: skip
TIMINGS = ("fit_seconds", "predict_ms")
"""evaluate's measured times: the only figures that differ between two runs."""

Args = Callable[[Path], list[str]]
"""The command line of a scenario writing into a fresh folder."""


def _rcbht(args: list[str]) -> float:
    """Wall seconds of one `rcbht` process."""
    started = time.perf_counter()
    subprocess.run(
        [sys.executable, "-m", "rcbht_introspection.cli", *args],
        check=True,
        stdout=subprocess.DEVNULL,
        stderr=subprocess.DEVNULL,
        cwd=REPO,
    )
    return time.perf_counter() - started


def _scrub(value: Any, out: str) -> Any:
    """A JSON value without timings and with its own output folder named OUT."""
    if isinstance(value, dict):
        return {k: _scrub(v, out) for k, v in value.items() if k not in TIMINGS}
    if isinstance(value, list):
        return [_scrub(v, out) for v in value]
    return value.replace(out, "OUT") if isinstance(value, str) else value


def _output(folder: Path) -> dict[str, Any]:
    """Every file a run wrote: JSON parsed and scrubbed, the rest as bytes."""
    out: dict[str, Any] = {}
    for path in sorted(p for p in folder.rglob("*") if p.is_file()):
        key = str(path.relative_to(folder))
        if path.suffix == ".json":
            out[key] = _scrub(json.loads(path.read_text()), str(folder))
        else:
            out[key] = path.read_bytes()
    return out


def _baxter_bags() -> list[str]:
    return [str(p) for p in sorted(BAXTER.glob("*/*.bag"))]


def _scenarios(imported: Path) -> dict[str, tuple[Path, Args]]:
    """Each command: (the data it needs, its command line writing into a folder)."""
    deviation = SHARED / "openhrp_deviation"
    return {
        "verify-eval": (deviation, lambda o: [
            "verify-eval", str(deviation), str(SHARED / "hiro" / "SIM_HIRO_ONE_SA_SUCCESS"),
            "--labels", str(deviation / "labels.csv"), "--json", str(o / "v.json")]),
        "evaluate": (REAL, lambda o: [
            "evaluate", str(REAL), "--permutations", "5", "--no-progress",
            "--json", str(o / "e.json")]),
        "sim": (REPO, lambda o: [
            "sim", "--trials", "40", "--progress", "off", "--out", str(o / "set")]),
        "label": (REAL, lambda o: ["label", str(REAL), "--out", str(o / "words")]),
        "bag import": (BAXTER, lambda o: [
            "bag", "import", *_baxter_bags(), "--out", str(o / "bags"), *BAXTER_IMPORT,
            "--json", str(o / "import.json")]),
        "calibrate": (REAL, lambda o: [
            "calibrate", str(REAL), "--out", str(o / "p.yaml"), "--report", str(o / "r.json")]),
        "audit": (imported, lambda o: [
            "audit", str(imported), "--json", str(o / "audit.json")]),
    }  # fmt: skip


def _scenario(data: Path, args: Args, tmp: Path) -> dict[str, Any]:
    """--jobs 1 and --jobs 2 alternating: wall times, the speed-up of medians, identical outputs."""
    if not data.exists():
        return {"skipped": f"no {data}"}
    walls: dict[int, list[float]] = {jobs: [] for jobs in JOBS}
    first: dict[str, Any] | None = None
    identical = True
    for repeat in range(max(REPEATS, 1)):
        for jobs in JOBS:
            folder = tmp / f"jobs{jobs}-{repeat}"
            folder.mkdir(parents=True)
            walls[jobs].append(_rcbht([*args(folder), "--jobs", str(jobs)]))
            output = _output(folder)
            first = output if first is None else first
            identical = identical and output == first
            shutil.rmtree(folder)
    medians = {jobs: statistics.median(w) for jobs, w in walls.items()}
    return {
        "wall_s": {str(j): [round(w, 2) for w in ws] for j, ws in walls.items()},
        "median_wall_s": {str(j): round(m, 2) for j, m in medians.items()},
        "speed_up": round(medians[1] / medians[2], 3),
        "identical_output": identical,
        "files": len(first or {}),
    }


def run(out_dir: Path) -> dict[str, Any]:
    """Every scenario (`RCBHT_BENCH_FLEET`: a comma-separated subset, e.g. evaluate,sim)."""
    chosen = os.environ.get("RCBHT_BENCH_FLEET", "")
    results: dict[str, Any] = {"cores": os.cpu_count(), "load_avg_at_start": os.getloadavg()}
    with tempfile.TemporaryDirectory() as tmp_name:
        tmp = Path(tmp_name)
        imported = tmp / "baxter"
        if BAXTER.is_dir() and (not chosen or "audit" in chosen.split(",")):
            _rcbht(["bag", "import", *_baxter_bags(), "--out", str(imported), *BAXTER_IMPORT])
        for name, (data, args) in _scenarios(imported).items():
            if chosen and name.replace(" ", "-") not in chosen.split(","):
                continue
            results[name] = _scenario(data, args, tmp / name.replace(" ", "-"))
    return results
