"""Progress of a long command on stderr: a tqdm bar on a terminal, plain lines otherwise.

A bar redraws itself with carriage returns; written to a log file or a pipe, that becomes
hundreds of frames. Off a terminal the same progress is a line at every tenth of the work (and
one at the end), e.g. `svm/compact: 24/240 steps (10%), 3.1 s`.
"""

from __future__ import annotations

import math
import sys
import time
from typing import Protocol, TextIO

PLAIN_STEPS = 10
"""Lines a plain progress prints over the whole work (one per tenth), besides the last."""


class Progress(Protocol):
    """What a command calls: `update(n)` after n more units, `close()` at the end."""

    def update(self, n: int = 1) -> object: ...

    def close(self) -> None: ...


class PlainProgress:
    """A line on `stream` each time another 1/`steps` of `total` is done, and at close."""

    def __init__(
        self, total: int, desc: str, unit: str, stream: TextIO, steps: int = PLAIN_STEPS
    ) -> None:
        self.total, self.desc, self.unit, self.stream = total, desc, unit, stream
        self.steps = max(1, steps)
        self.done = 0
        self.shown = 0
        self.start = time.monotonic()

    def _next_mark(self) -> int:
        """Units done at which the next line is due."""
        k = math.floor(self.shown * self.steps / self.total) + 1 if self.total > 0 else 1
        return max(self.shown + 1, math.ceil(k * self.total / self.steps))

    def update(self, n: int = 1) -> None:
        self.done += n
        if self.total > 0 and self.done >= self._next_mark():
            self._line()

    def _line(self) -> None:
        share = f" ({100 * self.done / self.total:.0f}%)" if self.total > 0 else ""
        elapsed = time.monotonic() - self.start
        print(
            f"{self.desc}: {self.done}/{self.total} {_plural(self.unit)}{share}, {elapsed:.1f} s",
            file=self.stream,
            flush=True,
        )
        self.shown = self.done

    def close(self) -> None:
        if self.done != self.shown or self.done == 0:
            self._line()


def _plural(unit: str) -> str:
    """step -> steps, teach -> teaches."""
    return unit + ("es" if unit.endswith(("ch", "sh", "s", "x")) else "s")


def is_terminal(stream: TextIO) -> bool:
    """True when `stream` is an interactive terminal."""
    try:
        return stream.isatty()
    except (AttributeError, ValueError):  # a closed or stand-in stream
        return False


def progress_bar(total: int, desc: str, unit: str, stream: TextIO | None = None) -> Progress:
    """A tqdm bar when `stream` (default stderr) is a terminal and tqdm is installed (an
    optional extra), else a PlainProgress."""
    stream = sys.stderr if stream is None else stream
    if is_terminal(stream):
        try:
            from tqdm import tqdm
        except ImportError:
            return PlainProgress(total, desc, unit, stream)
        bar: Progress = tqdm(total=total, desc=desc, unit=unit, file=stream)
        return bar
    return PlainProgress(total, desc, unit, stream)
