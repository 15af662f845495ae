"""`make bench`: run every benchmark module, print medians, write bench_out/results.json.

Each module in BENCHMARKS exposes `run(out_dir: Path) -> dict` returning its measured figures.
Benchmarks are measurements, never pass/fail tests. The modules in OPTIONAL (the one-hour soak,
the SIGINT stop loop, teaching) run only when named with --only, and write their own
bench_out/<name>.json, so they neither slow `make bench` nor replace its results.json.
"""

from __future__ import annotations

import argparse
import importlib
import json
import signal
import sys
import time
from pathlib import Path

from rcbht_introspection.bench.machine import machine

BENCHMARKS: tuple[str, ...] = (
    "rcbht_introspection.bench.taxonomy",
    "rcbht_introspection.bench.stream",
    "rcbht_introspection.bench.mondrian",
    "rcbht_introspection.bench.belief",
    "rcbht_introspection.bench.verifier",
    "rcbht_introspection.bench.fleet",
    "rcbht_introspection.bench.sim",
    "rcbht_introspection.bench.ros",
)
OPTIONAL: tuple[str, ...] = (
    "rcbht_introspection.bench.soak",
    "rcbht_introspection.bench.stops",
    "rcbht_introspection.bench.teach",
)


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(prog="python -m rcbht_introspection.bench")
    parser.add_argument("--out", type=Path, default=Path("bench_out"))
    parser.add_argument("--only", nargs="*", help="benchmark module short names to run")
    args = parser.parse_args(argv)
    # SIGTERM takes Ctrl-C's path: the running module's finally blocks stop its node processes
    signal.signal(signal.SIGTERM, signal.default_int_handler)
    args.out.mkdir(parents=True, exist_ok=True)
    results: dict[str, object] = {
        "machine": machine(),
        "started": time.strftime("%Y-%m-%d %H:%M:%S"),
    }
    regular = False
    for name in BENCHMARKS + OPTIONAL:
        short = name.rsplit(".", 1)[1]
        optional = name in OPTIONAL
        if (args.only or optional) and short not in (args.only or ()):
            continue
        module = importlib.import_module(name)
        print(f"== {short}", flush=True)
        try:
            figures = module.run(args.out)
        except KeyboardInterrupt:  # Ctrl-C: the module's finally blocks stopped its processes
            print(f"{short}: interrupted; nothing written", file=sys.stderr)
            return 0
        print(json.dumps(figures, indent=2), flush=True)
        if optional:
            own = args.out / f"{short}.json"
            own.write_text(json.dumps({**results, short: figures}, indent=2))
            print(f"wrote {own}")
        else:
            results[short] = figures
            regular = True
    if regular:
        (args.out / "results.json").write_text(json.dumps(results, indent=2))
        print(f"wrote {args.out / 'results.json'}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
