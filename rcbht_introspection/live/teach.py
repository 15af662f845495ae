"""What the classifier session asks of teaching (learn/teaching.py builds it): requests, status,
taught models. Here as plain types so the live core needs nothing from learn/."""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any, Protocol

from rcbht_introspection.live.belief import BeliefTracker


@dataclass(frozen=True)
class TeachRequest:
    """One label for one window (the Teach service's request, the TeachRequest message)."""

    label: str
    """A sub-task name or a failure class; '' asks for the status only."""
    last: bool = True
    """The sub-task that ended last in the current stream; False: [start, end]."""
    start: float = 0.0
    end: float = 0.0
    request_id: str = ""
    """A re-sent request with the same id is answered again, not taught twice."""


@dataclass(frozen=True)
class TeachStatus:
    """The answer to a request, and where teaching stands."""

    accepted: bool
    message: str
    pending: int
    """Requests taken but not yet in a model handed to the live path."""
    taught_windows: int
    model_version: int
    """Models handed to the live path so far."""
    errors: int
    """Requests refused and updates failed so far."""


class Teacher(Protocol):
    """Labelled windows in, taught models out (learn/teaching.Teaching), on the live thread."""

    waiting: list[Any]
    """Accepted windows whose words are not all final yet."""

    def request(self, req: TeachRequest, tracker: BeliefTracker) -> TeachStatus: ...

    def collect(self, tracker: BeliefTracker, stream_ends: bool = False) -> None: ...

    def take_model(self) -> Any | None: ...
