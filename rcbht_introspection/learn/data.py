"""Sub-task samples from dataset folders, trial folders or bags, with golden or engine words."""

from __future__ import annotations

from collections.abc import Iterable
from dataclasses import dataclass
from pathlib import Path

from rcbht_introspection.errors import InputError
from rcbht_introspection.grammar.split import SubtaskSample, split_words
from rcbht_introspection.io import bags
from rcbht_introspection.io.hiro import ARMS, find_trials, read_state, read_trial
from rcbht_introspection.io.rcbht_format import level_path, read_trial_words
from rcbht_introspection.io.trial import SUBTASKS
from rcbht_introspection.learn import WORD_SOURCES, WordSource
from rcbht_introspection.taxonomy.batch import label_trial
from rcbht_introspection.taxonomy.words import AXES, LEVELS, TrialWords


@dataclass
class TrialSamples:
    """The samples of one trial and where its words came from."""

    trial: str
    path: Path
    source: str
    samples: list[SubtaskSample]

    @property
    def complete(self) -> bool:
        """True when every sub-task of SUBTASKS has a sample."""
        return [s.subtask for s in self.samples] == list(SUBTASKS)


def _golden_arms(folder: Path) -> list[tuple[str, Path]]:
    """(arm, golden root) pairs present in a trial folder (golden/ or golden/<arm>/)."""
    root = folder / "golden"
    found = []
    for arm in ARMS:
        for candidate in (root / arm, root / f"{arm}_golden"):
            if level_path(candidate, LEVELS[0], AXES[0]).is_file():
                found.append((arm, candidate))
                break
    if not found and level_path(root, LEVELS[0], AXES[0]).is_file():
        found.append(("R", root))
    return found


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


def load_trial_samples(path: Path, words: WordSource = "auto") -> TrialSamples:
    """Samples of one trial folder or bag; `words` picks golden files or the batch engine."""
    if words not in WORD_SOURCES:
        raise InputError(f"unknown word source {words!r} (known: {', '.join(WORD_SOURCES)})")
    path = Path(path)
    if path.is_file() and bags.is_bag(path):
        if words == "golden":
            raise InputError("a bag has no golden label files; use words='engine'", path)
        trial = bags.read_trial_bag(path)
        trial_words = label_trial(trial)
        samples = split_words(trial_words, trial.state_times, trial.end_time)
        return TrialSamples(trial.name, path, "engine", samples)
    golden = _golden_arms(path)
    if words == "golden" or (words == "auto" and golden):
        if not golden:
            raise InputError("no golden/ label files in this trial", path)
        trial_words = TrialWords(name=path.name)
        for arm, root in golden:
            part = read_trial_words(root, name=path.name, arm=arm, levels=LEVELS)
            trial_words.words.update(part.words)
        state = read_state(path / "R_State.dat") or read_state(path / "L_State.dat")
        samples = split_words(trial_words, state, _end_time(path))
        return TrialSamples(path.name, path, "golden", samples)
    trial = read_trial(path)
    samples = split_words(label_trial(trial), trial.state_times, trial.end_time)
    return TrialSamples(trial.name, path, "engine", samples)


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


def load_trials(paths: Iterable[Path | str], words: WordSource = "auto") -> list[TrialSamples]:
    """Per-trial samples of every trial under `paths`."""
    if words not in WORD_SOURCES:
        raise InputError(f"unknown word source {words!r} (known: {', '.join(WORD_SOURCES)})")
    return [load_trial_samples(p, words) for p in find_inputs(paths)]


def load_samples(paths: Iterable[Path | str], words: WordSource = "auto") -> list[SubtaskSample]:
    """All sub-task samples of the trials under `paths` (dataset dirs, trial dirs or bags)."""
    return [s for trial in load_trials(paths, words) for s in trial.samples]
