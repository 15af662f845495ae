"""classifier_node's model: which file it classifies with (the taught teach_file, else
model_file), whether that is usable or a cold start, and the teach queue built beside it."""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

from rcbht_introspection.configure.params import ClassifierConfig
from rcbht_introspection.learn.live import load_live_config
from rcbht_introspection.learn.model_file import load_subtask_model
from rcbht_introspection.learn.models import SubtaskModel
from rcbht_introspection.learn.online import load_teach_config
from rcbht_introspection.learn.teaching import Teaching
from rcbht_introspection.live.belief import UNKNOWN
from rcbht_introspection.live.health import ModelStatus, file_sha256

Note = tuple[str, str]
"""(log level: info, warning or error; one line)."""


@dataclass
class ModelSource:
    """The model in use, the file it came from (and its hash), and why it is not usable ('')."""

    model: SubtaskModel | None
    path: str
    problem: str
    cold: bool
    """Teaching with no model file yet: /task_state stays unknown until the first window."""
    sha256: str

    def about(self) -> str:
        """The model's taxonomy profile, for the node's start-up line ('' without a model)."""
        if self.model is None:
            return ""
        sha = self.model.taxonomy_sha256[:12] or "not recorded"
        return f", taxonomy profile {self.model.taxonomy_profile} (sha256 {sha})"

    def status(self, prediction_error: str | None) -> ModelStatus:
        """The model for /diagnostics, with the latest prediction error."""
        return ModelStatus(self.path, self.sha256, self.problem, prediction_error)

    def taught(self, cfg: ClassifierConfig, teaching: Teaching) -> None:
        """A taught model is in use: name its file and hash (the teach worker's) from now on."""
        if teaching.saved_sha256:
            self.path, self.sha256 = teaching_file(cfg), teaching.saved_sha256

    def notes(self) -> list[Note]:
        """What to log at configure: a cold start, or why no model is used."""
        if self.cold:
            where = self.path or "model_file not set"
            return [
                (
                    "info",
                    f"cold start: no model yet ({where}), /task_state stays {UNKNOWN!r} until the first taught window",
                )
            ]
        if self.model is None:
            return [("error", f"no usable model, /task_state stays {UNKNOWN!r}: {self.problem}")]
        return []


def model_source(cfg: ClassifierConfig) -> ModelSource:
    """A teaching node continues from the model it saved (teach_file), else from model_file."""
    taught = cfg.teach_enabled and cfg.teach_file and Path(cfg.teach_file).is_file()
    path = cfg.teach_file if taught else cfg.model_file
    model, problem = load_subtask_model(path, cfg.expected_profile)
    cold = cfg.teach_enabled and model is None and not Path(path).is_file()
    return ModelSource(model, path, "" if cold else problem, cold, file_sha256(path))


def teaching_file(cfg: ClassifierConfig) -> str:
    """Where taught models are saved ('' when they are not)."""
    return cfg.teach_file or cfg.model_file


def node_teaching(
    cfg: ClassifierConfig, source: ModelSource, counts: dict[str, int]
) -> tuple[Teaching, list[Note]]:
    """The teach queue and worker, and what to log; a model file that exists but is unusable
    is not overwritten (teaching refuses, saying why)."""
    unusable = (
        f"model file {source.path} exists but is not usable ({source.problem}); "
        "teaching would overwrite it"
        if source.model is None and not source.cold
        else ""
    )
    teaching = Teaching(
        load_teach_config(cfg.teach_config_file or None),
        source.model,
        teaching_file(cfg),
        counts,
        taxonomy_profile=cfg.expected_profile or "reference",  # what a cold start records
        live_windows=load_live_config(),  # running windows are taught too (config/live.yaml)
        unavailable=unusable,  # then no learner process is started
    )
    if teaching.unavailable:
        return teaching, [("error", f"teaching is unavailable: {teaching.unavailable}")]
    if not teaching_file(cfg):
        return teaching, [("warning", "teaching: taught models are not saved (no teach_file)")]
    return teaching, []


def classifier_model(
    cfg: ClassifierConfig, counts: dict[str, int]
) -> tuple[ModelSource, Teaching | None, list[Note]]:
    """classifier_node's model, its teaching (None when off) and what to log at configure."""
    source = model_source(cfg)
    if not cfg.teach_enabled:
        return source, None, source.notes()
    teaching, notes = node_teaching(cfg, source, counts)
    return source, teaching, [*source.notes(), *notes]


def teaching_values(teaching: Teaching) -> list[tuple[str, str]]:
    """The teaching values of the classifier's /diagnostics status."""
    status = teaching.status()
    return [
        ("taught windows", str(status.taught_windows)),
        ("teach requests pending", str(status.pending)),
        ("taught model version", str(status.model_version)),
        ("teach learner", teaching.where_learned()),
    ]
