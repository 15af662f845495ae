"""The README's quick start runs as written, on simulated trials instead of the HIRO data.

The three bash blocks of "## Quick start" are read from README.md and run in a temporary folder:
train and evaluate (after the `rcbht sim` line that makes the data), bag conversion, replay and
scoring, then the pip-only live lines (both nodes and the recorder in the background, a bag
replayed into them, Ctrl-C). `ros2 ...` lines need the ros2 CLI, which PyPI lacks; the pip-only
lines beside them are their documented equivalents. SUBSTITUTIONS turns HIRO names into the
names of the simulated trials; each of them must still occur in the README.
"""

from __future__ import annotations

import os
import re
import subprocess
import sys
from pathlib import Path

import pytest
from ros_support import REPO, require_ros, ros_env

from rcbht_introspection.replay.supervision import stop_process
from rcbht_introspection.waiting import wait_until

pytestmark = [pytest.mark.ros, pytest.mark.slow]

README = REPO / "README.md"
SUBSTITUTIONS = (
    ("../shared/data/hiro/REAL_HIRO_ONE_SA_SUCCESS", "sim5"),
    ("--trials 12", "--trials 5"),
    ("--out sim12", "--out sim5"),
    ("rcbht train sim12", "rcbht train sim5"),
    ("$D/*-S-0? $D/*-S-[123]? $D/*-S-40", "$D/*-S-0[1-4]"),  # trials 1-4 for training
    ("--permutations 20", "--permutations 1"),
    ("bags/20121127-HIROSA-S-41.mcap", "bags/SIM-ONE-S-05.mcap"),  # the held-out trial
    ("bags/*-4[1-6].mcap", "bags/*-05.mcap"),
    (".venv/bin/", ""),  # the test's PATH starts with the venv's bin
)
"""(README text, what runs instead on the simulated set). Five trials are the fewest that keep
every command meaningful: a training set of several trials, a held-out one for replay, a
learning curve of more than one step; each more trial costs seconds in five of the commands."""
COMMAND_S = 600.0


def quick_start_blocks() -> list[list[str]]:
    """The commands of each bash block of the quick start, comments and blank lines dropped."""
    text = README.read_text()
    section = text.split("## Quick start", 1)[1].split("\n## ", 1)[0]
    blocks = []
    for body in re.findall(r"```bash\n(.*?)```", section, flags=re.S):
        lines = []
        for line in body.splitlines():
            line = re.sub(r"\s+#.*$", "", line).strip()
            if line and not line.startswith("#"):
                lines.append(line)
        blocks.append(lines)
    return blocks


def substituted(line: str) -> str:
    for readme_text, instead in SUBSTITUTIONS:
        line = line.replace(readme_text, instead)
    return line


def run(line: str, cwd: Path, env: dict[str, str]) -> str:
    proc = subprocess.run(
        ["bash", "-c", "set -e\n" + line],
        cwd=cwd,
        env=env,
        capture_output=True,
        text=True,
        timeout=COMMAND_S,
    )
    assert proc.returncode == 0, f"{line!r} exited {proc.returncode}:\n{proc.stderr[-3000:]}"
    return proc.stdout


def test_every_substitution_matches_the_readme() -> None:
    text = README.read_text()
    missing = [readme_text for readme_text, _ in SUBSTITUTIONS if readme_text not in text]
    assert not missing, f"README no longer contains {missing}: update SUBSTITUTIONS"
    assert len(quick_start_blocks()) == 3


def test_quick_start_runs_as_written(tmp_path: Path) -> None:
    require_ros()
    train, replay, live = quick_start_blocks()
    env = ros_env(tmp_path)
    env["PATH"] = str(Path(sys.executable).parent) + os.pathsep + env.get("PATH", "")
    work = tmp_path / "work"
    work.mkdir()

    # train and evaluate: the simulated set first (it is what $D names here)
    d_line = substituted(next(line for line in train if line.startswith("D=")))
    sim = [line for line in train if line.startswith("rcbht sim ")]
    assert sim, "the train block makes simulated trials"
    for line in sim + [line for line in train if line not in sim]:
        run(d_line + "\n" + substituted(line), work, env)
    for name in ("model.rcbht", "curve.json", "curve.png", "sim.rcbht"):
        assert (work / name).stat().st_size > 0, name

    # bag conversion, replay and scoring through the real nodes
    d_line = substituted(next(line for line in replay if line.startswith("D=")))
    for line in replay:
        if not line.startswith("D="):
            run(d_line + "\n" + substituted(line), work, env)
    assert '"subtask_accuracy"' in (work / "eval.json").read_text()

    # live: both nodes and the recorder in the background, a bag into them, Ctrl-C
    pip_only = [substituted(line) for line in live if not line.startswith("ros2 ")]
    background = [
        line for line in pip_only if "rcbht_introspection.nodes" in line or " record " in line
    ]
    foreground = [line for line in pip_only if line not in background]
    assert len(background) == 3 and len(foreground) == 1, pip_only
    logs = [tmp_path / f"live{i}.log" for i in range(len(background))]
    procs = []
    for line, log in zip(background, logs, strict=True):
        with log.open("w") as out:
            procs.append(
                subprocess.Popen(  # bash expands $PWD; exec: the signal reaches the process
                    ["bash", "-c", "exec " + line],
                    cwd=work,
                    env=env,
                    stdout=out,
                    stderr=subprocess.STDOUT,
                )
            )
    try:
        assert wait_until(
            lambda: all(
                "mode " in log.read_text()
                or "arms " in log.read_text()
                or "recording" in log.read_text()
                for log in logs
            ),
            timeout=120,
        ), [log.read_text()[-500:] for log in logs]
        run(foreground[0], work, env)
    finally:
        codes = [stop_process(proc, timeout=30) for proc in procs]
    assert codes == [0, 0, 0], [log.read_text()[-1500:] for log in logs]
    info = run("rcbht bag info states.mcap", work, env)
    count = re.search(r"/task_state\D+(\d+)", info)
    assert count and int(count.group(1)) > 0, info
