"""Import another robot's ROS 1 bag or rosbag2 bag as a trial bag of this project.

rosbags' AnyReader reads both formats and registers the message definitions the bag stores, so
custom message types decode without the robot's packages. The wrench of each arm comes from a
topic or field path (msg_paths), the sub-task phases from a string or integer field or a CSV file
(phase_events), the samples follow one counted stamp policy (wrench_samples) and are cut to
the phases: from the first task phase's start to the end phase or the first phase outside the
task (`-`) after it. Every count goes into an ImportReport,
which the output bag's trial info stores as its "import" record.
"""

from __future__ import annotations

import contextlib
import math
import re
from collections.abc import Iterator, Mapping, Sequence
from dataclasses import asdict, dataclass, field, replace
from pathlib import Path
from typing import Any, Literal, get_args

import numpy as np

from rcbht_introspection.errors import InputError
from rcbht_introspection.io.bags import END_PHASE, is_bag, write_trial_bag
from rcbht_introspection.io.msg_paths import (
    WRENCH,
    WRENCH_STAMPED,
    FieldPath,
    resolve_path,
    topic_listing,
)
from rcbht_introspection.io.phase_events import (
    OUT,
    PhaseCounts,
    PhaseCsv,
    TaskSpan,
    phase_name,
    read_phase_csv,
    task_span,
    usable_phases,
)
from rcbht_introspection.io.sensor_checks import frozen_runs
from rcbht_introspection.io.trial import Trial, check_phases
from rcbht_introspection.io.wrench_samples import ArmCounts, WrenchSamples, align
from rcbht_introspection.task import Task

StampSource = Literal["auto", "header", "receive"]
STAMP_SOURCES: tuple[str, ...] = get_args(StampSource)
DEFAULT_ARM = "R"
ARM_NAME = re.compile(r"[A-Za-z][A-Za-z0-9_]*")
_NS = 10**9


@dataclass(frozen=True)
class ImportOptions:
    """Where a bag's wrench and phases are, and how to stamp and sample them."""

    wrench: Mapping[str, str] = field(default_factory=dict)
    """Arm -> topic or field path of a WrenchStamped/Wrench; empty: the bag's one wrench topic
    as arm R."""
    phase: str = ""
    """Topic or field path of a string phase, or of an integer phase (with phase_map)."""
    phase_map: Mapping[int, str] | None = None
    """Integer phase value -> name ('' = the end phase, '-' = outside the task)."""
    out_of_task: tuple[str, ...] = ()
    """Phase names outside the task (besides '-'), e.g. ('idle',): skipped before the first task
    phase; the first after a task phase ends the trial."""
    phase_csv: Path | None = None
    """A `time,phase` or `stamp,phase` CSV file instead of `phase`."""
    end_phases: tuple[str, ...] = (END_PHASE,)
    """Phase names that end the trial (END_PHASE is appended at the last sample if none comes)."""
    stamps: StampSource = "auto"
    """'header' stamps, 'receive' (log) times, or 'auto': header when every wrench has one."""
    rate_hz: float | None = None
    """Resample every arm onto this fixed rate (linear interpolation); None keeps the samples."""
    task: Task | None = None
    """The task the trials belong to: stored in the bag; every phase must be one of its sub-tasks."""
    frozen: tuple[int, float] | None = None
    """Frozen-sensor thresholds (samples, seconds) of io/sensor_checks.frozen_runs; None: no check."""

    def check(self) -> None:
        """One named error for options that cannot work together."""
        if bool(self.phase) == (self.phase_csv is not None):
            raise InputError("give one phase source: a phase topic/field or a phase CSV")
        if self.phase_map is not None and not self.phase:
            raise InputError("a phase map applies to an integer phase field", field="--phase-map")
        if self.rate_hz is not None and not (math.isfinite(self.rate_hz) and self.rate_hz > 0):
            raise InputError(f"not a positive rate: {self.rate_hz}", field="--rate")
        if self.stamps not in STAMP_SOURCES:
            raise InputError(f"unknown stamp source {self.stamps!r}", field="--stamps")
        for arm in self.wrench:
            if not ARM_NAME.fullmatch(arm):
                raise InputError(f"not an arm name (letters, digits, _): {arm!r}", field="--wrench")
        if not self.end_phases or not all(n.strip() for n in self.end_phases):
            raise InputError("the end phase needs a name", field="--end-phase")
        both = sorted(set(self.end_phases) & {OUT, *self.out_of_task})
        if both:
            raise InputError(f"{both[0]!r} cannot end the trial and be outside the task")


def parse_wrench_specs(items: Sequence[str]) -> dict[str, str]:
    """['L=/left/ft', '/ft'] -> {'L': '/left/ft', 'R': '/ft'}: ARM=SPEC, or SPEC for arm R."""
    specs: dict[str, str] = {}
    for item in items:
        arm, sep, spec = item.partition("=")
        if not sep:
            arm, spec = DEFAULT_ARM, item
        if arm in specs:
            raise InputError(f"arm {arm} is given twice", field="--wrench")
        specs[arm] = spec
    return specs


@dataclass(frozen=True)
class ImportReport:
    """What an import read, dropped and wrote; stored as the trial info's "import" record."""

    bag: str
    stamps: str
    """'header' or 'receive': where the sample times came from."""
    arms: dict[str, ArmCounts]
    phase_source: str
    phase_counts: PhaseCounts
    subtasks: tuple[str, ...]
    """The trial's phase names in order."""
    samples: int
    """Samples per arm in the output bag."""
    rate_hz: float | None
    time_origin_ns: int
    """Stamp of the trial's first sample (the output bag keeps the input's stamps)."""
    findings: tuple[str, ...] = ()
    """Frozen-sensor runs of the written wrench (with ImportOptions.frozen), one line each."""

    def to_dict(self) -> dict[str, Any]:
        """Plain form for the trial info JSON."""
        out = asdict(self)
        out["subtasks"] = list(self.subtasks)
        out["findings"] = list(self.findings)
        return out

    def summary(self) -> str:
        """One line for the CLI: samples, every nonzero count, phases."""
        parts = [f"{self.samples} samples ({self.stamps} stamps)"]
        for arm, c in self.arms.items():
            dropped = [
                f"{n} {what}"
                for what, n in (
                    ("unset", c.unset),
                    ("repeated", c.repeated),
                    ("decreasing", c.decreasing),
                    ("before the first phase", c.before_first_phase),
                    ("after the end", c.after_end),
                )
                if n
            ]
            parts.append(
                f"{arm}: {c.kept} of {c.messages} kept"
                + (f", dropped {', '.join(dropped)}" if dropped else "")
            )
        p = self.phase_counts
        outside = f"{p.before_first_phase} outside the task before the first phase, "
        parts.append(
            f"phases {' > '.join(self.subtasks)} (end {p.end}; {p.events} events, "
            f"{p.repeated} repeated, {p.empty} empty, "
            f"{outside if p.before_first_phase else ''}{p.after_end} after the end)"
        )
        if self.rate_hz is not None:
            parts.append(f"resampled at {self.rate_hz:g} Hz")
        return "; ".join(parts)


def is_importable(path: Path | str) -> bool:
    """A ROS 1 bag (.bag file) or a rosbag2 bag (.mcap, .db3 or a bag directory)."""
    path = Path(path)
    return (path.is_file() and path.suffix == ".bag") or is_bag(path)


def import_name(path: Path | str) -> str:
    """Trial name of an input bag: its file name without suffix, or its directory name."""
    path = Path(path)
    return path.name if path.is_dir() else path.stem


@contextlib.contextmanager
def _open(path: Path) -> Iterator[Any]:
    """An open AnyReader; a missing or damaged bag is an InputError."""
    from rosbags.highlevel import AnyReader
    from rosbags.typesys import Stores, get_typestore

    if not is_importable(path):
        raise InputError("not a ROS 1 bag (.bag) or a rosbag2 bag (.mcap, .db3, directory)", path)
    try:
        reader = AnyReader([path], default_typestore=get_typestore(Stores.ROS2_JAZZY))
        reader.open()
    except Exception as exc:  # rosbags raises many types on damaged files
        raise InputError(f"cannot read bag: {exc}", path) from None
    try:
        yield reader
    finally:
        reader.close()


def _wrench_paths(
    options: ImportOptions, topics: Mapping[str, str | None], fielddefs: Any, bag: Path
) -> dict[str, FieldPath]:
    """Arm -> resolved wrench path (the bag's one wrench topic when none is given)."""
    specs = dict(options.wrench)
    if not specs:
        found = sorted(t for t, m in topics.items() if m in (WRENCH_STAMPED, WRENCH))
        if len(found) != 1:
            what = "no" if not found else "several"
            raise InputError(
                f"{what} WrenchStamped/Wrench topics ({topic_listing(topics)}): give --wrench ARM=SPEC",
                bag,
            )
        specs = {DEFAULT_ARM: found[0]}
    paths = {arm: resolve_path(spec, topics, fielddefs, bag) for arm, spec in specs.items()}
    for p in paths.values():
        if p.leaf not in (WRENCH_STAMPED, WRENCH):
            raise InputError(f"is {p.leaf}, not a WrenchStamped or Wrench", bag, field=p.spec)
    return paths


def _stamp_source(options: ImportOptions, arms: Mapping[str, FieldPath], bag: Path) -> str:
    """'header' or 'receive' for every arm."""
    headless = [p.spec for p in arms.values() if p.header is None]
    if options.stamps == "header" and headless:
        raise InputError(
            "no header to take a stamp from (use --stamps receive)", bag, field=headless[0]
        )
    if options.stamps == "auto":
        return "receive" if headless else "header"
    return options.stamps


def _phase_path(
    options: ImportOptions, topics: Mapping[str, str | None], fielddefs: Any, bag: Path
) -> FieldPath | None:
    """The resolved phase field (None with a phase CSV): a string, or an integer with a map."""
    if not options.phase:
        return None
    p = resolve_path(options.phase, topics, fielddefs, bag)
    if options.phase_map is not None and not p.is_integer:
        raise InputError(f"is {p.leaf}; --phase-map needs an integer field", bag, field=p.spec)
    if options.phase_map is None and p.is_integer:
        raise InputError(f"is {p.leaf}: give --phase-map VALUE=NAME,...", bag, field=p.spec)
    if not (p.is_integer or p.is_string):
        raise InputError(f"is {p.leaf}; a phase is a string or an integer", bag, field=p.spec)
    return p


def _read(
    reader: Any, arms: Mapping[str, FieldPath], phase: FieldPath | None, stamps: str, bag: Path
) -> tuple[dict[str, WrenchSamples], list[tuple[int | None, Any]]]:
    """Every arm's samples and the phase events (stamp of the reference arm's last kept sample
    received with or before it, None before the first; source value) in receive order."""
    samples = {arm: WrenchSamples(p.spec) for arm, p in arms.items()}
    reference = samples[next(iter(arms))]
    events: list[tuple[int | None, Any]] = []
    wanted = {p.topic for p in arms.values()} | ({phase.topic} if phase else set())
    connections = [c for c in reader.connections if c.topic in wanted]
    for conn, log_ns, raw in reader.messages(connections=connections):
        try:
            msg = reader.deserialize(raw, conn.msgtype)
        except Exception as exc:  # a message that does not match its definition
            raise InputError(
                f"cannot decode a {conn.msgtype} message: {exc}", bag, field=conn.topic
            ) from None
        for arm, p in arms.items():
            if p.topic == conn.topic:
                value = p.value(msg)
                stamp = p.header_stamp_ns(msg) if stamps == "header" else int(log_ns)
                samples[arm].add(stamp, value.wrench if p.leaf == WRENCH_STAMPED else value)
        if phase is not None and phase.topic == conn.topic:
            events.append((reference.last, phase.value(msg)))
    for arm, s in samples.items():
        if not s.stamps:
            raise InputError(
                f"no wrench samples of arm {arm} with a usable stamp", bag, field=s.source
            )
    return samples, events


def _named_events(
    options: ImportOptions,
    phase: FieldPath | None,
    events: list[tuple[int | None, Any]],
    table: PhaseCsv | None,
    first_ns: int,
    bag: Path,
) -> tuple[list[tuple[int, str | None]], str]:
    """(absolute stamp, phase name or None for the end) of every event, and the source's name."""
    if table is not None:
        source = str(table.path)
        timed = [
            (round(t * _NS) + (0 if table.absolute else first_ns), name) for t, name in table.rows
        ]
    else:
        assert phase is not None
        source = phase.spec
        timed = [(first_ns if s is None else s, v) for s, v in events]
    if not timed:
        raise InputError("no phase events", bag, field=source)
    named = [
        (s, phase_name(v, options.phase_map, options.end_phases, bag, source, options.out_of_task))
        for s, v in timed
    ]
    for _, name in named:
        if name == END_PHASE:  # not an end phase here, but the end phase of the written bag
            raise InputError(
                f"phase {END_PHASE!r} would end the trial in the written bag; name it in --end-phase",
                bag,
                field=source,
            )
    return named, source


def _span(named: list[tuple[int, str | None]], bag: Path, source: str) -> TaskSpan:
    """The task span of the named events; none is an error."""
    span = task_span(named)
    if not span.phases:
        what = "end phase" if span.end == "source" else "end of the phase events"
        raise InputError(
            f"no sub-task phase before the {what} (name values outside the task '-', e.g. "
            "--phase-map 0=-, or in --out-of-task)",
            bag,
            field=source,
        )
    return span


def _cut(
    samples: Mapping[str, WrenchSamples], span: TaskSpan, options: ImportOptions, bag: Path
) -> tuple[np.ndarray, dict[str, np.ndarray], dict[str, ArmCounts]]:
    """(stamps ns, wrench per arm, counts per arm) of the samples inside the span."""
    cut: dict[str, tuple[np.ndarray, np.ndarray]] = {}
    counts: dict[str, ArmCounts] = {}
    for arm, s in samples.items():
        stamps_ns, values, counts[arm] = s.cut(span.phases[0][0], span.end_ns, arm, bag)
        cut[arm] = (stamps_ns, values)
    stamp_ns, wrench = align(cut, options.rate_hz, bag)
    return stamp_ns, wrench, counts


def _check_task(options: ImportOptions, names: Sequence[str], bag: Path, source: str) -> None:
    """Every phase name is a sub-task of the --task file, if there is one."""
    if options.task is None:
        return
    strangers = sorted(set(names) - set(options.task.subtasks))
    if strangers:
        raise InputError(
            f"phases {strangers} are not sub-tasks of the task ({', '.join(options.task.subtasks)})",
            bag,
            field=source,
        )


def _findings(
    options: ImportOptions, time: np.ndarray, wrench: Mapping[str, np.ndarray], span: TaskSpan
) -> tuple[str, ...]:
    """Frozen-sensor runs of the written wrench and task phases after the end, one line each."""
    found = [
        run.describe(arm, len(time))
        for arm in sorted(wrench)
        for run in (frozen_runs(time, wrench[arm], *options.frozen) if options.frozen else ())
    ]
    if span.resumed:
        found.append(
            f"{span.resumed} task phase events after the trial's end ({span.end}): the task went "
            "on after it, and those phases are not in this trial"
        )
    return tuple(found)


def read_foreign_bag(path: Path | str, options: ImportOptions) -> tuple[Trial, ImportReport]:
    """The trial of a ROS 1 or rosbag2 bag of another robot, and what the import did."""
    path = Path(path)
    options.check()
    table = read_phase_csv(options.phase_csv) if options.phase_csv is not None else None
    with _open(path) as reader:
        topics = {name: info.msgtype for name, info in reader.topics.items()}
        fielddefs = reader.typestore.fielddefs
        arms = _wrench_paths(options, topics, fielddefs, path)
        stamps = _stamp_source(options, arms, path)
        phase = _phase_path(options, topics, fielddefs, path)
        samples, events = _read(reader, arms, phase, stamps, path)
    first_ns = samples[next(iter(arms))].stamps[0]
    named, source = _named_events(options, phase, events, table, first_ns, path)
    span = _span(named, path, source)
    stamp_ns, wrench, counts = _cut(samples, span, options, path)
    origin = int(stamp_ns[0])
    time = (stamp_ns - origin) / _NS
    starts = [(max(0.0, (s - origin) / _NS), name) for s, name in span.phases]
    usable, repeated, empty = usable_phases(starts, float(time[-1]))
    if not usable:
        raise InputError("no phase has samples", path, field=source)
    _check_task(options, [n for _, n in usable], path, source)
    phase_counts = PhaseCounts(
        len(named), repeated, empty, span.after_end, span.end, span.before_first_phase,
        span.resumed,
    )  # fmt: skip
    report = ImportReport(
        bag=str(path),
        stamps=stamps,
        arms=counts,
        phase_source=source,
        phase_counts=phase_counts,
        subtasks=tuple(n for _, n in usable),
        samples=len(time),
        rate_hz=options.rate_hz,
        time_origin_ns=origin,
        findings=_findings(options, time, wrench, span),
    )
    metadata: dict[str, object] = {"import": report.to_dict()}
    if options.task is not None:
        metadata["task"] = options.task.to_dict()
    trial = Trial(
        name=import_name(path),
        time=time,
        wrench=wrench,
        state_times=tuple(t for t, _ in usable),
        metadata=metadata,
        phases=report.subtasks,
    )
    check_phases(trial, path)
    return trial, report


def import_bag(path: Path | str, out: Path | str, options: ImportOptions) -> ImportReport:
    """Read a foreign bag (read_foreign_bag) and write it as a trial bag at `out`."""
    trial, report = read_foreign_bag(path, options)
    write_trial_bag(trial, out, time_origin_ns=report.time_origin_ns)
    return report


@dataclass(frozen=True)
class PlannedImport:
    """One bag of an import: its input, its output and its options (its own phase CSV)."""

    bag: Path
    out: Path
    options: ImportOptions

    def run(self) -> ImportReport:
        """Import it (import_bag; on any worker)."""
        return import_bag(self.bag, self.out, self.options)

    def __str__(self) -> str:
        return str(self.bag)


def plan_imports(
    paths: Sequence[Path | str], out_dir: Path | str, options: ImportOptions, suffix: str = ".mcap"
) -> list[PlannedImport]:
    """Each bag to `out_dir/<name><suffix>`, checked before any bag is read: one output each
    (names unique), none existing. A phase CSV folder holds `<name>.csv` for each bag; a CSV file
    serves a single bag only."""
    inputs = [Path(p) for p in paths]
    names = [import_name(p) for p in inputs]
    for i, name in enumerate(names):
        if name in names[:i]:
            first = inputs[names.index(name)]
            raise InputError(
                f"two input bags are named {name!r}, {first} and {inputs[i]}: one output each"
            )
    csv = options.phase_csv
    if csv is not None and not csv.is_dir() and len(inputs) > 1:
        raise InputError("one CSV for several bags: give a folder of <bag name>.csv", csv)
    outs = [Path(out_dir) / f"{name}{suffix}" for name in names]
    for out in outs:  # before any bag is read: a long import should not fail at its end
        if out.exists():
            raise InputError("exists already, not overwriting", out)
    return [
        PlannedImport(
            path,
            out,
            options
            if csv is None or not csv.is_dir()
            else replace(options, phase_csv=csv / f"{name}.csv"),
        )
        for path, name, out in zip(inputs, names, outs, strict=True)
    ]
