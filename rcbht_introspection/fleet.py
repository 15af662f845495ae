"""Many inputs at once: the `--jobs` / `--scheduler` options of the offline commands, the
joblib backend they select, an ordered parallel map, and the rule for bad inputs among many.

Parallel runs (docs/your-robot.md, "Many recordings: --jobs and --scheduler"): `--jobs N` runs
the independent units of a command (trials, bags, permutations) on N joblib workers (loky
processes on this machine); `--scheduler ADDRESS` runs them on a dask.distributed cluster through joblib's
Dask backend (the `fleet` extra). Every unit is seeded by its own index, never by its worker,
and results are gathered in input order: the output is the same whatever N.

Bad inputs (docs/your-robot.md, "Bad input: counted, named, and the run goes on"): a command of
many inputs processes the others, names each bad one with its one-line reason (stderr and its
JSON's `bad_inputs`), and exits 0 when something was done, 2 with `--strict` or when nothing
could be done.

joblib and Dask are imported inside the functions: `rcbht --help` stays light, and the runtime
imports without Dask.
"""

from __future__ import annotations

import argparse
import contextlib
import functools
import sys
from collections.abc import Callable, Iterator, Sequence
from dataclasses import dataclass, field
from typing import Any, TypeVar

from rcbht_introspection.errors import InputError

T = TypeVar("T")
R = TypeVar("R")

STRICT_EXIT = 2
"""Exit code of a run with a bad input under --strict, or with nothing done."""


def add_parallel_options(parser: argparse.ArgumentParser, units: str = "trials") -> None:
    """Add `--jobs N` and `--scheduler ADDRESS` (the `units` are what runs in parallel)."""
    parser.add_argument(
        "--jobs",
        type=int,
        default=1,
        metavar="N",
        help=f"joblib workers (loky processes) for the {units}; -1: one per core (the output is "
        "the same whatever N)",
    )
    parser.add_argument(
        "--scheduler",
        default=None,
        metavar="ADDRESS",
        help=f"run the {units} on a dask.distributed scheduler (e.g. tcp://10.0.0.5:8786) through "
        "joblib's Dask backend (the fleet extra); --jobs is then the cluster's",
    )


def add_strict_inputs(parser: argparse.ArgumentParser, what: str = "input") -> None:
    """Add `--strict` to a command of many inputs: a bad one makes the exit code 2 (the others
    are processed all the same)."""
    parser.add_argument(
        "--strict",
        action="store_true",
        help=f"exit code {STRICT_EXIT} when any {what} is bad (the others are still processed; "
        "docs/your-robot.md, 'Bad input: counted, named, and the run goes on')",
    )


def jobs_from_args(args: argparse.Namespace) -> int:
    """The joblib worker count the options ask for (-1 with a scheduler: all its workers)."""
    jobs: int = args.jobs
    if jobs == 0 or jobs < -1:
        raise InputError(
            f"must be a positive count or -1 (one per core), not {jobs}", field="--jobs"
        )
    return -1 if args.scheduler else jobs


@contextlib.contextmanager
def backend(scheduler: str | None) -> Iterator[None]:
    """joblib's Dask backend on the scheduler at `scheduler` (None: joblib's default, loky); an
    unreachable scheduler fails after Dask's `distributed.comm.timeouts.connect` (30 s default)."""
    if scheduler is None:
        yield
        return
    try:
        from dask.distributed import Client
    except ImportError:
        raise InputError(
            "--scheduler needs Dask: pip install 'rcbht_introspection[fleet]'"
        ) from None
    from joblib import parallel_config

    try:
        client = Client(scheduler)  # type: ignore[no-untyped-call]
    except OSError as exc:
        raise InputError(f"--scheduler {scheduler}: {exc}") from None
    with client, parallel_config(backend="dask"):
        yield


def parallel_map(
    func: Callable[[T], R],
    items: Sequence[T],
    jobs: int = 1,
    progress: Callable[[int], object] | None = None,
) -> list[R]:
    """[func(item) for item in items] on `jobs` joblib workers, in the order of `items`
    (`progress` is called with 1 as each result arrives, in order). `jobs` 1 runs in this
    process without joblib; a backend set by the caller (backend()) is used otherwise."""
    if jobs == 1 or len(items) <= 1:
        out = []
        for item in items:
            out.append(func(item))
            if progress is not None:
                progress(1)
        return out
    from joblib import Parallel, delayed

    results: list[R] = []
    for result in Parallel(n_jobs=jobs, return_as="generator")(delayed(func)(i) for i in items):
        results.append(result)
        if progress is not None:
            progress(1)
    return results


@dataclass(frozen=True)
class Failed:
    """An input that could not be used, and the one-line reason."""

    input: str
    reason: str


def attempt(func: Callable[[T], R], item: T) -> R | Failed:
    """func(item), or Failed(str(item), the one-line reason) when it raises an InputError."""
    try:
        return func(item)
    except InputError as exc:
        return Failed(str(item), str(exc))


@dataclass
class BadInputs:
    """The bad inputs of one command run: named, counted, and the exit code they give."""

    command: str
    total: int = 0
    failed: list[Failed] = field(default_factory=list)

    def add(self, failed: Failed) -> None:
        self.failed.append(failed)

    def keep(self, outcomes: Sequence[R | Failed]) -> list[R]:
        """The results among `outcomes` (each Failed is recorded)."""
        self.total += len(outcomes)
        kept: list[R] = []
        for outcome in outcomes:
            if isinstance(outcome, Failed):
                self.add(outcome)
            else:
                kept.append(outcome)
        return kept

    def collect(
        self, func: Callable[[T], R], items: Sequence[T], jobs: int = 1, strict: bool = False
    ) -> list[R]:
        """[func(item) for item in items] on `jobs` workers (parallel_map), each item whose
        InputError is recorded left out (`strict`: the first one raised); when none of these
        `items` could be used, an InputError (check_some, on this call's items alone)."""
        part = BadInputs(self.command)
        kept = part.keep(
            parallel_map(func if strict else functools.partial(attempt, func), items, jobs)
        )
        part.check_some()
        self.total += part.total
        self.failed.extend(part.failed)
        return kept

    def lines(self) -> list[str]:
        """One stderr line per bad input, then one summary line (none: no bad input)."""
        if not self.failed:
            return []
        each = [
            f"rcbht {self.command}: left out: "
            + (f.reason if f.input in f.reason else f"{f.input}: {f.reason}")
            for f in self.failed
        ]
        names = ", ".join(f.input for f in self.failed[:3])
        more = f" and {len(self.failed) - 3} more" if len(self.failed) > 3 else ""
        return [
            *each,
            f"rcbht {self.command}: {len(self.failed)} of {self.total} inputs bad, left out "
            f"({names}{more}); --strict makes the exit code {STRICT_EXIT}",
        ]

    def to_dict(self) -> dict[str, Any]:
        """The JSON's `bad_inputs` record."""
        return {
            "count": len(self.failed),
            "of": self.total,
            "inputs": [{"input": f.input, "reason": f.reason} for f in self.failed],
        }

    def check_some(self) -> None:
        """An InputError when every input was bad: the one input's own error, or for several,
        each named on stderr and one line that none could be used."""
        if not self.failed or len(self.failed) < self.total:
            return
        if self.total == 1:
            raise InputError(self.failed[0].reason)
        for line in self.lines()[:-1]:
            print(line, file=sys.stderr)
        raise InputError(f"none of the {self.total} inputs could be used (each named above)")

    def finish(self, strict: bool) -> int:
        """Print the lines naming the bad inputs; the exit code: 0, or 2 when there was a bad
        input and `strict` (call check_some first: nothing done is an error)."""
        for line in self.lines():
            print(line, file=sys.stderr)
        return STRICT_EXIT if strict and self.failed else 0
