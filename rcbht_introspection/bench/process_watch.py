"""RSS and CPU of a running process from /proc, sampled over a run, and their growth over a window."""

from __future__ import annotations

import os
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any


def proc_status(pid: int) -> tuple[float, float] | None:
    """(RSS MiB, CPU seconds user+system) of a live process from /proc, None when it is gone."""
    try:
        status = Path(f"/proc/{pid}/status").read_text()
        stat = Path(f"/proc/{pid}/stat").read_text()
    except OSError:
        return None
    rss_kib = 0
    for line in status.splitlines():
        if line.startswith("VmRSS:"):
            rss_kib = int(line.split()[1])
            break
    fields = stat.rsplit(")", 1)[1].split()
    ticks = int(fields[11]) + int(fields[12])  # utime, stime (fields 14 and 15 of stat)
    return rss_kib / 1024.0, ticks / os.sysconf("SC_CLK_TCK")


@dataclass
class Tracked:
    """One sampled process: its RSS/CPU series (seconds since the soak started) and its end."""

    name: str
    pid: int
    started_s: float
    samples: list[tuple[float, float, float]] = field(default_factory=list)
    """(t s, RSS MiB, CPU s)"""
    exit_code: int | None = None
    stopped: bool = False
    stop_s: float | None = None
    ended_s: float | None = None

    def sample(self, t: float) -> None:
        got = proc_status(self.pid)
        if got is not None:
            self.samples.append((round(t, 2), round(got[0], 2), round(got[1], 2)))


def growth(samples: list[tuple[float, float, float]], window_s: float) -> dict[str, Any]:
    """RSS growth (percent) from the sample nearest `window_s` before the last one to the last."""
    if len(samples) < 2:
        return {"window_s": window_s, "growth_pct": None, "max_growth_pct": None}
    end = samples[-1][0]
    start = min(range(len(samples) - 1), key=lambda i: abs(samples[i][0] - (end - window_s)))
    inside = samples[start:]
    first = inside[0][1]
    return {
        "window_s": round(end - inside[0][0], 1),
        "growth_pct": round(100.0 * (inside[-1][1] - first) / first, 2) if first else None,
        "max_growth_pct": round(100.0 * (max(s[1] for s in inside) - first) / first, 2)
        if first
        else None,
    }


def process_figures(p: Tracked, run_end_s: float, window_s: float) -> dict[str, Any]:
    """RSS series and its growth (the run's last window if the process lived through it, else
    the last half of its own life), CPU, exit code."""
    s = p.samples
    lived = (s[-1][0] - s[0][0]) if s else 0.0
    covers = bool(s) and s[0][0] <= run_end_s - window_s + 1e-6 and s[-1][0] >= run_end_s - 1.0
    out: dict[str, Any] = {
        "pid": p.pid,
        "started_s": round(p.started_s, 1),
        "ended_s": round(p.ended_s, 1) if p.ended_s is not None else None,
        "rss_mib": [[t, rss] for t, rss, _ in s],
        "rss_start_mib": s[0][1] if s else None,
        "rss_end_mib": s[-1][1] if s else None,
        "rss_peak_mib": max(x[1] for x in s) if s else None,
        "cpu_s": s[-1][2] if s else None,
        "cpu_pct": round(100.0 * (s[-1][2] - s[0][2]) / lived, 1) if lived > 0 else None,
        "growth_over": "last window of the run" if covers else "last half of its life",
        **growth(s, window_s if covers else lived / 2),
        "exit_code": p.exit_code,
        "stop_s": p.stop_s,
    }
    return out
