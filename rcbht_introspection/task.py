"""A robot's task: its sub-task names in order and the phase names that end a trial.

The task comes from the data: the phase events of the training recordings name the sub-tasks
(bags: the /task_phase strings; trial folders: a `task.yaml` beside the state files, else the
HIRO snap assembly). A model file carries its task, so nodes, evaluation and plots take the names
from there. Rule for a trial's phase sequence (docs/your-robot.md): each phase event starts a
segment named by it; an end phase ends the trial; a name that comes again gives another sample of
that sub-task; a sub-task missing from a trial gives no sample of it.
"""

from __future__ import annotations

from collections.abc import Iterable, Sequence
from dataclasses import dataclass
from pathlib import Path

from rcbht_introspection.config_files import load_config
from rcbht_introspection.errors import InputError

TASK_FILE = "task.yaml"
"""Name of the task file beside a trial folder's state files (or in its dataset folder)."""


@dataclass(frozen=True)
class Task:
    """Sub-task names in their usual order, and the phase names that say the trial is over."""

    subtasks: tuple[str, ...]
    end_phases: tuple[str, ...] = ("done",)
    name: str = ""

    def to_dict(self) -> dict[str, object]:
        """Plain form for model-file headers and JSON reports."""
        return {
            "name": self.name,
            "subtasks": list(self.subtasks),
            "end_phases": list(self.end_phases),
        }

    @classmethod
    def from_dict(cls, data: dict[str, object]) -> Task:
        """Inverse of to_dict (a model-file header)."""
        subtasks = data.get("subtasks")
        end_phases = data.get("end_phases", ["done"])
        if not isinstance(subtasks, list) or not isinstance(end_phases, list):
            raise InputError("task: subtasks and end_phases must be lists of names")
        task = cls(
            tuple(map(str, subtasks)), tuple(map(str, end_phases)), str(data.get("name", ""))
        )
        check_task(task)
        return task


def check_task(task: Task) -> None:
    """Names are non-empty, distinct, and no sub-task is also an end phase."""
    if not task.subtasks:
        raise InputError("a task needs at least one sub-task", field="subtasks")
    for field, names in (("subtasks", task.subtasks), ("end_phases", task.end_phases)):
        for name in names:
            if not isinstance(name, str) or not name.strip() or name != name.strip():
                raise InputError(f"not a usable name: {name!r}", field=field)
        if len(set(names)) != len(names):
            raise InputError(f"a name is given twice: {list(names)}", field=field)
    both = sorted(set(task.subtasks) & set(task.end_phases))
    if both:
        raise InputError(f"{both} named both as sub-task and as end phase", field="end_phases")


HIRO_TASK = Task(("approach", "rotation", "insertion", "mating"), ("done",), "hiro-snap")
"""The HIRO snap assembly of the seed paper: the default task of trial folders and old models."""


def task_from_sequences(
    sequences: Iterable[Sequence[str]], end_phases: Sequence[str] = ("done",), name: str = ""
) -> Task:
    """The task whose sub-tasks are the names of the phase sequences, in their usual order.

    Each sequence (up to its first end phase) says that a name comes after the one before it; the
    names are sorted so that these precedences hold (a topological order), and where they do not
    decide (or contradict each other), the name seen first in the recordings comes first.
    """
    ends = set(end_phases)
    first_seen: dict[str, tuple[int, int]] = {}
    after: dict[str, set[str]] = {}
    for i, sequence in enumerate(sequences):
        previous: str | None = None
        for j, phase in enumerate(sequence):
            if phase in ends:
                break
            first_seen.setdefault(phase, (i, j))
            after.setdefault(phase, set())
            if previous is not None and previous != phase:
                after[phase].add(previous)
            previous = phase
    if not first_seen:
        raise InputError("no sub-task names in the phase events of the recordings")
    order: list[str] = []
    left = sorted(first_seen, key=first_seen.__getitem__)
    while left:
        ready = [n for n in left if not (after[n] & set(left))]
        chosen = ready[0] if ready else left[0]  # a contradiction: the name seen first
        order.append(chosen)
        left.remove(chosen)
    task = Task(tuple(order), tuple(end_phases), name)
    check_task(task)
    return task


def task_of_names(
    sequences: Iterable[Sequence[str]], end_phases: Sequence[str] = ("done",)
) -> Task:
    """HIRO's task when every name is one of its sub-tasks (old data and models), else the task
    of these phase sequences (task_from_sequences)."""
    sequences = [list(s) for s in sequences]
    if {n for s in sequences for n in s} <= set(HIRO_TASK.subtasks):
        return HIRO_TASK
    return task_from_sequences(sequences, end_phases)


def load_task_file(path: Path | str) -> Task:
    """A task file: `subtasks: [names in order]`, optional `end_phases` and `name`."""
    return load_config(Task, path, check=check_task)


def task_of_folder(folder: Path) -> Task:
    """The task of a trial folder: its task.yaml, its dataset's task.yaml, else HIRO's."""
    for candidate in (folder / TASK_FILE, folder.parent / TASK_FILE):
        if candidate.is_file():
            return load_task_file(candidate)
    return HIRO_TASK


__all__ = [
    "HIRO_TASK",
    "TASK_FILE",
    "Task",
    "check_task",
    "load_task_file",
    "task_from_sequences",
    "task_of_folder",
    "task_of_names",
]
