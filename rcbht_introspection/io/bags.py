"""rosbag2 trial bags via rosbags (no ROS install needed): write, read and recognise them.

A trial bag holds geometry_msgs/WrenchStamped on /wrench (one arm) or /<arm>/wrench (two arms),
std_msgs/String sub-task events on /task_phase (the trial's phase names at its state times, then
END_PHASE at the last sample) and one std_msgs/String JSON record on /rcbht/trial_info (name,
outcome, time origin, and the INFO_RECORDS the trial's metadata holds). Stamps are TIME_ORIGIN_NS + trial time, so no stamp is zero.
The storage follows the suffix: `x.mcap` / `x.db3` is one storage file; any other path is a
rosbag2 directory (MCAP inside). Reading accepts storage files and rosbag2 directories.
"""

from __future__ import annotations

import contextlib
import functools
import json
import shutil
import struct
import sys
import tempfile
from collections.abc import Iterator, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np
from numpy.typing import NDArray
from rosbags.interfaces import Connection
from rosbags.interfaces.typing import Typesdict
from rosbags.typesys import Stores, get_types_from_msg, get_typestore
from rosbags.typesys.store import Typestore

from rcbht_introspection.errors import InputError
from rcbht_introspection.io.sensor_checks import (
    REPEATED_METADATA,
    RepeatedPolicy,
    resolve_repeated_stamps,
)
from rcbht_introspection.io.trial import AXES, Trial, check_phases

# rosbags.rosbag2 (readers, writers, storage plugins: ~150 ms) is imported where a bag is opened,
# so that `rcbht --help`, which reaches this module through learn/data.py, does not pay for it
if TYPE_CHECKING:
    from rosbags.rosbag2 import StoragePlugin

WRENCH_TYPE = "geometry_msgs/msg/WrenchStamped"
STRING_TYPE = "std_msgs/msg/String"
PHASE_TOPIC = "/task_phase"
TRIAL_INFO_TOPIC = "/rcbht/trial_info"
END_PHASE = "done"
"""Phase name written at the last sample: the task is over (the segmenter flushes its streams)."""
TIME_ORIGIN_NS = 1_700_000_000 * 10**9
"""Absolute stamp of trial time 0 in written bags (a zero stamp means 'unset' in ROS)."""
BAG_SUFFIXES = (".mcap", ".db3")
INFO_RECORDS = ("task", "import", "failure")
"""Trial metadata records that the trial info carries as JSON objects: the trial's task, for
an imported bag what the import read and dropped (io/bag_import.py), and for a simulated failure
its class, onset and deviation (sim/simulate.py)."""
_NS = 10**9


def wrench_topic(arm: str, arms: tuple[str, ...]) -> str:
    """/wrench for a one-arm trial, /<arm>/wrench when there are two arms."""
    return "/wrench" if len(arms) == 1 else f"/{arm}/wrench"


def arm_of_topic(topic: str, frame_id: str) -> str:
    """Arm of a wrench topic: /<arm>/wrench, else the header frame_id when it names an arm, else R."""
    parts = topic.strip("/").split("/")
    if len(parts) >= 2 and parts[-1] == "wrench":
        return parts[-2]
    return frame_id if frame_id in ("L", "R") else "R"


def _typestore() -> Typestore:
    """The Jazzy typestore plus rcbht_interfaces (when its .msg files can be found)."""
    store = get_typestore(Stores.ROS2_JAZZY)
    msg_dir = interface_msg_dir()
    if msg_dir is not None:
        types: Typesdict = {}
        for f in sorted(msg_dir.glob("*.msg")):
            types.update(get_types_from_msg(f.read_text(), f"rcbht_interfaces/msg/{f.stem}"))
        store.register(types)
    return store


def interface_msg_dir() -> Path | None:
    """Folder of the rcbht_interfaces .msg files: installed share/ copy, else the source tree."""
    candidates = []
    try:
        from ament_index_python.packages import get_package_share_directory

        candidates.append(Path(get_package_share_directory("rcbht_interfaces")) / "msg")
    except Exception:  # not on AMENT_PREFIX_PATH: fall back below
        pass
    candidates.append(Path(sys.prefix) / "share" / "rcbht_interfaces" / "msg")
    candidates.append(Path(__file__).resolve().parents[2] / "msg_defs" / "msg")
    for c in candidates:
        if (c / "Word.msg").is_file():
            return c
    return None


def is_bag(path: Path | str) -> bool:
    """True for a .mcap/.db3 storage file or a rosbag2 directory (metadata.yaml inside)."""
    path = Path(path)
    if path.is_dir():
        return (path / "metadata.yaml").is_file()
    return path.is_file() and path.suffix in BAG_SUFFIXES


def stamp_ns(sec: int, nanosec: int) -> int:
    """builtin_interfaces/Time as integer nanoseconds."""
    return int(sec) * _NS + int(nanosec)


def _storage_plugin(suffix: str) -> StoragePlugin:
    from rosbags.rosbag2 import StoragePlugin

    return StoragePlugin.SQLITE3 if suffix == ".db3" else StoragePlugin.MCAP


class BagWriter:
    """A rosbag2 writer that ends as one storage file (x.mcap / x.db3) or a bag directory."""

    def __init__(self, path: Path | str) -> None:
        from rosbags.rosbag2 import Writer

        self.path = Path(path)
        if self.path.exists():
            raise InputError("exists already, not overwriting", self.path)
        self.path.parent.mkdir(parents=True, exist_ok=True)
        self.single_file = self.path.suffix in BAG_SUFFIXES
        self._tmp: Path | None = None
        self._dir = self.path
        if self.single_file:
            tmp = Path(tempfile.mkdtemp(prefix=".bag-", dir=self.path.parent))
            self._tmp, self._dir = tmp, tmp / self.path.stem
        self.store = _typestore()
        self._writer = Writer(
            self._dir, version=9, storage_plugin=_storage_plugin(self.path.suffix or ".mcap")
        )
        self._writer.open()
        self._connections: dict[str, Connection] = {}

    def connection(self, topic: str, msgtype: str) -> Connection:
        """The connection of `topic` (created on first use)."""
        conn = self._connections.get(topic)
        if conn is None:
            conn = self._writer.add_connection(topic, msgtype, typestore=self.store)
            self._connections[topic] = conn
        return conn

    def write_raw(self, topic: str, msgtype: str, t_ns: int, raw: bytes | memoryview) -> None:
        """Write already-serialised CDR bytes."""
        self._writer.write(self.connection(topic, msgtype), int(t_ns), raw)

    def write(self, topic: str, msg: Any, t_ns: int) -> None:
        """Serialise a rosbags message dataclass (each class names its `__msgtype__`), write it."""
        msgtype: str = msg.__msgtype__
        self.write_raw(topic, msgtype, t_ns, self.store.serialize_cdr(msg, msgtype))

    def close(self) -> None:
        """Finish the bag; a single-file bag is moved out of its temporary directory."""
        self._writer.close()
        if self.single_file:
            assert self._tmp is not None
            storage = next(self._dir.glob(f"*{self.path.suffix}"))
            shutil.move(str(storage), self.path)
            shutil.rmtree(self._tmp, ignore_errors=True)

    def abort(self) -> None:
        """Remove a partly written bag."""
        with contextlib.suppress(Exception):  # best effort clean-up
            self._writer.close()
        shutil.rmtree(self._tmp or self._dir, ignore_errors=True)

    def __enter__(self) -> BagWriter:
        return self

    def __exit__(self, exc_type: object, exc: object, tb: object) -> None:
        if exc_type is None:
            self.close()
        else:
            self.abort()


def trial_phase_events(trial: Trial, end_phase: str = END_PHASE) -> list[tuple[float, str]]:
    """(time, name) /task_phase events of a trial: each sub-task start, then `end_phase` at the end."""
    events = [
        (float(t), name) for t, name in zip(trial.state_times, trial.phase_names, strict=False)
    ]
    events.append((trial.end_time, end_phase))
    return events


def write_trial_bag(trial: Trial, path: Path | str, time_origin_ns: int = TIME_ORIGIN_NS) -> None:
    """Write `trial` as a bag (.mcap or .db3 storage file by suffix; other paths: a bag directory)."""
    path = Path(path)
    with BagWriter(path) as bag:
        store = bag.store
        Time = store.types["builtin_interfaces/msg/Time"]
        Header = store.types["std_msgs/msg/Header"]
        String = store.types[STRING_TYPE]
        Wrench = store.types["geometry_msgs/msg/Wrench"]
        WrenchStamped = store.types[WRENCH_TYPE]
        Vector3 = store.types["geometry_msgs/msg/Vector3"]
        t_ns = time_origin_ns + np.rint(np.asarray(trial.time, dtype=np.float64) * _NS).astype(
            np.int64
        )
        info = {
            "name": trial.name,
            "outcome": trial.outcome,
            "time_origin_ns": int(time_origin_ns),
            "arms": list(trial.arms),
        }
        for key in INFO_RECORDS:  # task: Task.to_dict; import: ImportReport.to_dict; failure: sim
            if isinstance(trial.metadata.get(key), dict):
                info[key] = trial.metadata[key]
        bag.write(TRIAL_INFO_TOPIC, String(data=json.dumps(info)), int(t_ns[0]))
        events = trial_phase_events(trial)
        ev = 0
        arms = trial.arms
        topics = {arm: wrench_topic(arm, arms) for arm in arms}
        for i, t in enumerate(t_ns):
            stamp = Time(sec=int(t // _NS), nanosec=int(t % _NS))
            for arm in arms:
                w = trial.wrench[arm][i]
                msg = WrenchStamped(
                    header=Header(stamp=stamp, frame_id=arm),
                    wrench=Wrench(
                        force=Vector3(x=float(w[0]), y=float(w[1]), z=float(w[2])),
                        torque=Vector3(x=float(w[3]), y=float(w[4]), z=float(w[5])),
                    ),
                )
                bag.write(topics[arm], msg, int(t))
            # An event follows the last sample before it (a sample at its exact time ends the
            # previous sub-task, spec 2.7); its log time is the event time.
            next_t = int(t_ns[i + 1]) if i + 1 < len(t_ns) else None
            while ev < len(events):
                e_ns = time_origin_ns + round(events[ev][0] * _NS)
                if next_t is not None and e_ns >= next_t:
                    break
                bag.write(PHASE_TOPIC, String(data=events[ev][1]), max(e_ns, int(t)))
                ev += 1


@dataclass(frozen=True)
class BagMessage:
    """One message of a bag in playback order: topic, type, log time (ns) and CDR bytes."""

    topic: str
    msgtype: str
    t_ns: int
    raw: bytes


def bag_messages(path: Path | str) -> Iterator[BagMessage]:
    """All messages of a bag in log-time order (ties keep the written order)."""
    from rosbags.rosbag2 import Reader

    path = Path(path)
    if not is_bag(path):
        raise InputError("not a rosbag2 bag (.mcap, .db3 or a bag directory)", path)
    try:
        with Reader(path) as reader:
            items = [
                (t, i, BagMessage(conn.topic, conn.msgtype, t, bytes(raw)))
                for i, (conn, t, raw) in enumerate(reader.messages())
            ]
    except InputError:
        raise
    except Exception as exc:  # rosbags raises many types on damaged files
        raise InputError(f"cannot read bag: {exc}", path) from None
    items.sort(key=lambda x: (x[0], x[1]))
    for _, _, m in items:
        yield m


_CDR_LE = b"\x00\x01\x00\x00"
_CDR_HEADER = struct.Struct("<2s2xiII")
_WRENCH_TAIL = struct.Struct("<6d")


@functools.cache
def _wrench_struct(frame_len: int) -> struct.Struct:
    """CDR layout of a WrenchStamped whose frame_id (with its NUL) is `frame_len` bytes."""
    pad = (-(12 + frame_len)) % 8  # the doubles align to 8 relative to the payload start
    return struct.Struct(f"<4siII{frame_len}s{pad}x6d")


def encode_wrench(stamp: int, frame_id: str, values: Sequence[float]) -> bytes:
    """Little-endian CDR of a geometry_msgs/WrenchStamped (what rclpy publishes as raw bytes)."""
    frame = frame_id.encode() + b"\x00"
    sec, nanosec = divmod(int(stamp), _NS)
    return _wrench_struct(len(frame)).pack(_CDR_LE, sec, nanosec, len(frame), frame, *values)


def decode_wrench_sample(raw: bytes) -> tuple[int, tuple[float, ...]]:
    """(stamp ns, (Fx..Mz)) of a little-endian CDR WrenchStamped: the live per-sample path
    (segmenter_node at 1 kHz per arm), which does not need the frame id."""
    kind, sec, nanosec, n = _CDR_HEADER.unpack_from(raw)
    if kind != b"\x00\x01":
        raise ValueError("not little-endian CDR")
    off = 16 + n
    off += (-(off - 4)) % 8  # doubles align to 8 relative to the CDR payload start
    return sec * _NS + nanosec, _WRENCH_TAIL.unpack_from(raw, off)


def decode_wrench(raw: bytes) -> tuple[int, str, tuple[float, ...]]:
    """(stamp ns, frame_id, (Fx..Mz)) of a little-endian CDR WrenchStamped, without a typestore."""
    stamp, values = decode_wrench_sample(raw)
    (n,) = struct.unpack_from("<I", raw, 12)
    frame = raw[16 : 16 + n - 1].decode() if n else ""
    return stamp, frame, values


def decode_string(raw: bytes) -> str:
    """data of a little-endian CDR std_msgs/String."""
    (n,) = struct.unpack_from("<I", raw, 4)
    return raw[8 : 8 + n - 1].decode()


@dataclass
class _BagRecords:
    """What a trial bag holds, decoded: wrench samples per arm, phase events and the trial info."""

    info: dict[str, Any] = field(default_factory=dict)
    stamps: dict[str, list[int]] = field(default_factory=dict)
    values: dict[str, list[tuple[float, ...]]] = field(default_factory=dict)
    phases: list[tuple[int, int, str]] = field(default_factory=list)
    """(log time, stamp of the last sample before it, name) of each /task_phase event."""


def _read_bag_records(path: Path) -> _BagRecords:
    """Decode the wrench, phase and trial-info messages of a bag in one pass over it."""
    records = _BagRecords()
    last_stamp = 0
    for m in bag_messages(path):
        try:
            if m.msgtype == WRENCH_TYPE:
                t, frame, w = decode_wrench(m.raw)
                arm = arm_of_topic(m.topic, frame)
                records.stamps.setdefault(arm, []).append(t)
                records.values.setdefault(arm, []).append(w)
                last_stamp = max(last_stamp, t)
            elif m.topic == PHASE_TOPIC and m.msgtype == STRING_TYPE:
                records.phases.append((m.t_ns, last_stamp, decode_string(m.raw)))
            elif m.topic == TRIAL_INFO_TOPIC and m.msgtype == STRING_TYPE:
                records.info = json.loads(decode_string(m.raw))
        except (ValueError, struct.error, UnicodeDecodeError, json.JSONDecodeError) as exc:
            raise InputError(f"malformed {m.msgtype} message: {exc}", path, field=m.topic) from None
    if not records.stamps:
        raise InputError("no WrenchStamped messages (/wrench or /<arm>/wrench)", path)
    return records


def _arm_arrays(
    records: _BagRecords, repeated: RepeatedPolicy | None
) -> tuple[dict[str, NDArray[np.int64]], dict[str, NDArray[np.float64]], dict[str, dict[str, int]]]:
    """Stamps and wrench per arm as arrays, with repeated stamps resolved when a policy is given
    (counts per arm), so each arm's samples have distinct stamps as the live node sees them."""
    repeats: dict[str, dict[str, int]] = {}
    arm_stamp: dict[str, NDArray[np.int64]] = {}
    wrench: dict[str, NDArray[np.float64]] = {}
    for arm in sorted(records.stamps):
        arm_stamps = np.asarray(records.stamps[arm], dtype=np.int64)
        arm_values = np.asarray(records.values[arm], dtype=np.float64).reshape(-1, len(AXES))
        if repeated is not None and bool((np.diff(arm_stamps) >= 0).all()):
            arm_stamps, arm_values, repeats[arm] = resolve_repeated_stamps(
                arm_stamps, arm_values, repeated
            )
        arm_stamp[arm], wrench[arm] = arm_stamps, arm_values
    return arm_stamp, wrench, repeats


def _shared_stamps(arm_stamp: dict[str, NDArray[np.int64]], path: Path) -> NDArray[np.int64]:
    """The first arm's stamps, after checking every other arm was sampled at the same instants
    (within 1 us): a trial has one time axis for all arms."""
    arms = sorted(arm_stamp)
    ref = arm_stamp[arms[0]]
    for arm in arms[1:]:
        other = arm_stamp[arm]
        if len(other) != len(ref) or np.any(np.abs(other - ref) > 1000):
            raise InputError(f"arm {arm} stamps differ from arm {arms[0]}'s", path, field="stamp")
    return ref


def _trial_time(
    ref: NDArray[np.int64], origin: int, repeated: RepeatedPolicy | None, path: Path
) -> NDArray[np.float64]:
    """Trial time in seconds from `origin`; it must increase (the taxonomy divides by steps)."""
    time: NDArray[np.float64] = (ref - origin) / _NS
    if np.any(np.diff(time) <= 0):
        k = int(np.argmax(np.diff(time) <= 0)) + 1
        hint = "; see --repeated-stamps" if repeated is None and time[k] == time[k - 1] else ""
        raise InputError(f"wrench stamps do not increase at message {k}{hint}", path, field="stamp")
    return time


def _phase_starts(
    records: _BagRecords, end_phases: Sequence[str], first_stamp: int, origin: int
) -> tuple[list[float], list[str], int]:
    """(start times, names) of the sub-tasks before the first end phase, and the number of
    events from the end phase on (the end phase itself included)."""
    state: list[float] = []
    names: list[str] = []
    after_end = 0
    for log_ns, sample_ns, phase in records.phases:
        phase = phase.strip()
        if phase in end_phases or after_end:
            after_end += 1
            continue
        # written bags log events at their trial time; recorded ones at receive time, so
        # there the event belongs to the last sample received before it
        t = log_ns if records.info else (sample_ns or first_stamp)
        state.append((t - origin) / _NS)
        names.append(phase)
    return state, names, after_end


def read_trial_bag(
    path: Path | str,
    end_phases: Sequence[str] = (END_PHASE,),
    repeated: RepeatedPolicy | None = None,
) -> Trial:
    """Trial of a bag written by write_trial_bag or recorded live (/wrench or /<arm>/wrench).

    Every /task_phase event before the first end phase starts a sub-task of that name; events
    after it are counted in metadata['events_after_end'] and not used. A wrench stamp equal to
    the previous one is an error, or with a `repeated` policy resolved as segmenter_node does
    (io/sensor_checks; counts per arm in metadata['repeated_stamps'])."""
    path = Path(path)
    records = _read_bag_records(path)
    info = records.info
    arm_stamp, wrench, repeats = _arm_arrays(records, repeated)
    ref = _shared_stamps(arm_stamp, path)
    origin = int(info.get("time_origin_ns", ref[0]))
    time = _trial_time(ref, origin, repeated, path)
    state, names, after_end = _phase_starts(records, end_phases, int(ref[0]), origin)
    trial = Trial(
        name=str(info.get("name", path.name.split(".")[0])),
        time=time,
        wrench=wrench,
        state_times=tuple(state),
        outcome=str(info.get("outcome", "success")),
        metadata={
            "bag": str(path),
            "events_after_end": max(0, after_end - 1),
            **{key: info[key] for key in INFO_RECORDS if isinstance(info.get(key), dict)},
            **({REPEATED_METADATA: repeats} if repeats else {}),
        },
        phases=tuple(names),
    )
    check_phases(trial, path)
    return trial
