"""Sub-task samples from dataset folders, trial folders or bags, with golden or engine words."""

from __future__ import annotations

from collections.abc import Iterable
from dataclasses import dataclass
from pathlib import Path

from rcbht_introspection.errors import InputError
from rcbht_introspection.grammar.split import SubtaskSample, split_words
from rcbht_introspection.io import bags
from rcbht_introspection.io.conformance import golden_roots
from rcbht_introspection.io.hiro import (
    ARMS,
    dropped_state_times,
    find_trials,
    read_trial,
    trial_state_times,
)
from rcbht_introspection.io.rcbht_format import read_trial_words
from rcbht_introspection.io.sensor_checks import RepeatedPolicy, trial_findings
from rcbht_introspection.io.trial import Trial
from rcbht_introspection.learn import WORD_SOURCES, WordSource
from rcbht_introspection.live.intake import IntakeConfig
from rcbht_introspection.summaries.blocks import trial_tracks
from rcbht_introspection.task import HIRO_TASK, Task, task_of_folder, task_of_names
from rcbht_introspection.taxonomy.batch import label_trial
from rcbht_introspection.taxonomy.config import TaxonomyConfig, is_reference
from rcbht_introspection.taxonomy.stream import StreamConfig
from rcbht_introspection.taxonomy.words import LEVELS, TrialWords


@dataclass
class TrialSamples:
    """The samples of one trial and where its words came from."""

    trial: str
    path: Path
    source: str
    samples: list[SubtaskSample]
    task: Task = HIRO_TASK
    """The task the trial belongs to (its folder's task.yaml, or the names of its phases)."""
    findings: tuple[str, ...] = ()
    """Problems of the trial's wrench (io/sensor_checks.trial_findings), when it was read."""
    repeated: RepeatedPolicy | None = None
    """The repeated-stamp policy the trial was read with (None: a repeated stamp is an error)."""
    dropped_state_times: int = 0
    """State times the trial's state file had after its last sample or out of order: dropped
    (io/hiro.read_state_times)."""

    @property
    def complete(self) -> bool:
        """True when the trial runs its task's sub-tasks once each, in order."""
        return self.covers(self.task)

    def covers(self, task: Task) -> bool:
        """True when the trial's sub-tasks are `task`'s, once each, in order."""
        return [s.subtask for s in self.samples] == list(task.subtasks)


def task_of_trials(trials: Iterable[TrialSamples]) -> Task:
    """The one task of a set of trials: their common task, else the names of all their phases."""
    trials = list(trials)
    tasks = {t.task for t in trials}
    if len(tasks) == 1:
        return tasks.pop()
    return task_of_names([s.subtask for s in t.samples] for t in trials)


def _end_time(folder: Path) -> float:
    """Last time stamp of the trial's torque file (the end of its last sub-task)."""
    for arm in ARMS:
        path = folder / f"{arm}_Torques.dat"
        if path.is_file():
            with path.open("rb") as handle:
                handle.seek(0, 2)
                size = handle.tell()
                handle.seek(max(0, size - 4096))
                lines = [
                    ln for ln in handle.read().decode(errors="replace").splitlines() if ln.strip()
                ]
            try:
                return float(lines[-1].split()[0])
            except (IndexError, ValueError):
                return read_trial(folder).end_time
    raise InputError("no R_Torques.dat or L_Torques.dat", folder)


def load_trial_samples(
    path: Path,
    words: WordSource = "auto",
    taxonomy: TaxonomyConfig | None = None,
    repeated: RepeatedPolicy | None = None,
    checks: IntakeConfig | None = None,
    stream: StreamConfig | None = None,
    strict: bool = False,
) -> TrialSamples:
    """Samples of one trial folder or bag; `words` picks golden files or the batch engine.

    `taxonomy` labels engine words (None: reference) and `stream` picks the stream profile whose
    words they are (None: reference; causal and live as the segmenter emits them). The golden
    files hold the reference profiles' words, so with another profile 'auto' means the engine
    and 'golden' is an error.
    A trial whose wrench is read (engine words) is resolved with the `repeated` stamp policy
    and checked for a frozen sensor (thresholds of `checks`, default IntakeConfig()).
    A state time after the last sample or out of order is dropped and counted, or with `strict`
    an error (io/hiro.read_state_times).
    """
    if words not in WORD_SOURCES:
        raise InputError(f"unknown word source {words!r} (known: {', '.join(WORD_SOURCES)})")
    path = Path(path)
    checks = checks or IntakeConfig()
    exact = stream is None or stream.profile == "reference"
    reference = (taxonomy is None or is_reference(taxonomy)) and exact
    if words == "golden" and not reference:
        name = (
            f"stream profile {stream.profile!r}"
            if stream is not None and not exact
            else f"{taxonomy.profile if taxonomy else 'reference'!r}"
        )
        raise InputError(
            f"golden label files hold the reference profile's words, not {name}'s; "
            "use words='engine'",
            path,
        )
    if path.is_file() and bags.is_bag(path):
        if words == "golden":
            raise InputError("a bag has no golden label files; use words='engine'", path)
        return _bag_samples(path, taxonomy, repeated, checks, stream)
    golden = list(golden_roots(path).items()) if reference else []
    if words == "golden" or (words == "auto" and golden):
        if not golden:
            raise InputError("no golden/ label files in this trial", path)
        return _golden_samples(path, golden, strict)
    trial = read_trial(path, repeated, strict)
    samples = _split(trial, taxonomy, stream)
    found = tuple(trial_findings(trial, checks.frozen_samples, checks.frozen_s))
    task = task_of_folder(path)
    dropped = dropped_state_times(trial)
    return TrialSamples(trial.name, path, "engine", samples, task, found, repeated, dropped)


def _bag_samples(
    path: Path,
    taxonomy: TaxonomyConfig | None,
    repeated: RepeatedPolicy | None,
    checks: IntakeConfig,
    stream: StreamConfig | None,
) -> TrialSamples:
    """Samples of a trial bag, with engine words."""
    trial = bags.read_trial_bag(path, repeated=repeated)
    samples = _split(trial, taxonomy, stream)
    found = tuple(trial_findings(trial, checks.frozen_samples, checks.frozen_s))
    return TrialSamples(trial.name, path, "engine", samples, task_of_bag(trial), found, repeated)


def _split(
    trial: Trial, taxonomy: TaxonomyConfig | None, stream: StreamConfig | None
) -> list[SubtaskSample]:
    """The trial's sub-task samples: engine words and the wrench block means."""
    words = label_trial(trial, taxonomy, stream)
    tracks = trial_tracks(trial)
    return split_words(words, trial.state_times, trial.end_time, trial.phase_names, tracks)


def _golden_samples(path: Path, golden: list[tuple[str, Path]], strict: bool) -> TrialSamples:
    """Samples of a trial folder from its golden label files (the words of the original code)."""
    trial_words = TrialWords(name=path.name)
    for arm, root in golden:
        part = read_trial_words(root, name=path.name, arm=arm, levels=LEVELS)
        trial_words.words.update(part.words)
    end = _end_time(path)
    states = trial_state_times(path, end, strict)
    task = task_of_folder(path)
    times, phases = states.named(task)
    tracks = trial_tracks(read_trial(path, strict=strict))
    samples = split_words(trial_words, times, end, phases or task.subtasks, tracks)
    return TrialSamples(
        path.name, path, "golden", samples, task, dropped_state_times=len(states.dropped)
    )


def task_of_bag(trial: Trial) -> Task:
    """A bag's task: the one its writer stored (trial info 'task'), else its own phase names."""
    stored = trial.metadata.get("task")
    if isinstance(stored, dict):
        return Task.from_dict(stored)
    return task_of_names([trial.phase_names])


def read_any_trial(
    path: Path | str, repeated: RepeatedPolicy | None = None, strict: bool = False
) -> Trial:
    """A trial folder or a bag (as find_inputs lists them) as a Trial (`repeated`: the
    repeated-stamp policy, None: a repeated stamp is an error; `strict`: a state time after the
    data or out of order is an error instead of dropped, io/hiro.read_trial)."""
    if Path(path).is_file() and bags.is_bag(path):
        return bags.read_trial_bag(path, repeated=repeated)
    return read_trial(path, repeated, strict)


def find_inputs(paths: Iterable[Path | str]) -> list[Path]:
    """Trial folders and bag files among `paths` (dataset folders are expanded, sorted)."""
    found: list[Path] = []
    for p in map(Path, paths):
        if p.is_file() and bags.is_bag(p):
            found.append(p)
        elif p.is_dir() and not find_trials_safe(p):
            found.extend(sorted(c for c in p.iterdir() if c.is_file() and bags.is_bag(c)))
        else:
            found.extend(find_trials([p]))
    if not found:
        raise InputError("no trials found", ", ".join(map(str, paths)))
    return found


def find_trials_safe(path: Path) -> list[Path]:
    """find_trials that returns [] instead of raising for a folder without trials."""
    try:
        return find_trials([path])
    except InputError:
        return []


def load_trials(
    paths: Iterable[Path | str],
    words: WordSource = "auto",
    taxonomy: TaxonomyConfig | None = None,
    repeated: RepeatedPolicy | None = None,
    checks: IntakeConfig | None = None,
    stream: StreamConfig | None = None,
    strict: bool = False,
) -> list[TrialSamples]:
    """Per-trial samples of every trial under `paths` (see load_trial_samples)."""
    if words not in WORD_SOURCES:
        raise InputError(f"unknown word source {words!r} (known: {', '.join(WORD_SOURCES)})")
    return [
        load_trial_samples(p, words, taxonomy, repeated, checks, stream, strict)
        for p in find_inputs(paths)
    ]


def load_samples(
    paths: Iterable[Path | str],
    words: WordSource = "auto",
    taxonomy: TaxonomyConfig | None = None,
) -> list[SubtaskSample]:
    """All sub-task samples of the trials under `paths` (dataset dirs, trial dirs or bags)."""
    return [s for trial in load_trials(paths, words, taxonomy) for s in trial.samples]
