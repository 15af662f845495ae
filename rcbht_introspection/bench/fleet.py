"""verify-eval on joblib workers: `--jobs 2` against `--jobs 1` on the same set, same machine.

The set is the OpenHRP deviation failures with the SIM_HIRO_ONE_SA_SUCCESS nominal runs (from
$RCBHT_SHARED_DATA or ../shared/data beside the repository), 5 folds with the anchors' methods,
as `rcbht verify-eval` runs it; without that data the benchmark reports it skipped. The two
JSON outputs must be equal byte for byte; the figure is the wall-time speed-up.
"""

from __future__ import annotations

import json
import os
import subprocess
import sys
import tempfile
import time
from pathlib import Path
from typing import Any

REPO = Path(__file__).resolve().parents[2]
SHARED = Path(os.environ.get("RCBHT_SHARED_DATA", REPO.parent / "shared" / "data"))
JOBS = (1, 2)


def _verify_eval(data: Path, jobs: int, out: Path) -> float:
    """Wall seconds of one `rcbht verify-eval` process (its own interpreter, as a user runs it)."""
    args = [
        sys.executable, "-m", "rcbht_introspection.cli", "verify-eval",
        str(data / "openhrp_deviation"), str(data / "hiro" / "SIM_HIRO_ONE_SA_SUCCESS"),
        "--labels", str(data / "openhrp_deviation" / "labels.csv"),
        "--jobs", str(jobs), "--json", str(out),
    ]  # fmt: skip
    started = time.perf_counter()
    subprocess.run(args, check=True, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
    return time.perf_counter() - started


def run(out_dir: Path) -> dict[str, Any]:
    """Wall time of --jobs 1 and --jobs 2, their speed-up and whether the JSON is identical."""
    if not (SHARED / "openhrp_deviation").is_dir():
        return {"skipped": f"no OpenHRP set under {SHARED}"}
    with tempfile.TemporaryDirectory() as tmp:
        walls = {j: _verify_eval(SHARED, j, Path(tmp) / f"jobs{j}.json") for j in JOBS}
        texts = {j: (Path(tmp) / f"jobs{j}.json").read_text() for j in JOBS}
    summary = json.loads(texts[1])
    return {
        "set": "openhrp_deviation + SIM_HIRO_ONE_SA_SUCCESS, 5 folds, peers",
        "runs": summary["runs"],
        "wall_s": {str(j): round(w, 2) for j, w in walls.items()},
        "speed_up": round(walls[1] / walls[2], 3),
        "identical_json": texts[1] == texts[2],
        "cores": os.cpu_count(),
    }
