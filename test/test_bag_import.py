"""`rcbht bag import`: another robot's ROS 1 / rosbag2 bags, written here with rosbags and custom
message types, become trial bags with the stamp policy's counts, the mapped phases, and a model
`rcbht train` can fit; bad input is one named line."""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass, replace
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np
import pytest
from conftest import HIRO, require
from ros_support import have

from rcbht_introspection.cli import main
from rcbht_introspection.errors import InputError

if TYPE_CHECKING:
    from rosbags.typesys.store import Typestore

TAGGED = "my_robot/msg/TaggedWrench"
TAGGED_MSG = "geometry_msgs/WrenchStamped wrench_stamped\nint32 tag\n"
DUAL = "my_robot/msg/DualArm"
DUAL_MSG = (
    "std_msgs/Header header\ngeometry_msgs/Wrench left\ngeometry_msgs/Wrench right\nstring phase\n"
)
PHASES = ("reach", "grasp", "insert")
PHASE_MAP = "0=reach,1=grasp,2=insert,3="
T0_NS = 1_600_000_000 * 10**9
STEP_NS = 10_000_000  # 100 Hz


@pytest.fixture(autouse=True)
def _rosbags() -> None:
    require(have("rosbags"), "rosbags not installed")


def phase_wrench(phase: int, u: np.ndarray, rng: np.random.Generator) -> np.ndarray:
    """(n, 6) wrench of one phase at fractions u in [0, 1): free motion, a pressing ramp, then an
    insertion with a wobble and a torque step; plus sensor noise."""
    n = len(u)
    w = np.zeros((n, 6))
    if phase == 0:
        w[:, 2] = -1.0
    elif phase == 1:
        w[:, 2] = -1.0 - 7.0 * u
        w[:, 0] = 1.5
    else:
        w[:, 2] = -8.0 + 3.0 * np.sin(2 * np.pi * 4 * u)
        w[:, 0] = 2.0 * np.sin(2 * np.pi * 3 * u)
        w[:, 4] = 0.8
    return w + rng.normal(scale=0.15, size=(n, 6))


@dataclass
class Recording:
    """What a test bag holds, as written: the truth an import is checked against."""

    stamps: list[int]
    log: list[int]
    tags: list[int]
    wrench: np.ndarray
    repeated: list[int]
    decreasing: list[int]

    def first(self, tag: int) -> int:
        return self.tags.index(tag)

    @property
    def kept(self) -> list[int]:
        """Indices the policy keeps: no repeated or decreasing stamp, up to the end tag."""
        dropped = set(self.repeated) | set(self.decreasing)
        return [i for i in range(self.first(len(PHASES)) + 1) if i not in dropped]


def recording(
    seed: int, repeated: Sequence[int] = (), decreasing: Sequence[int] = (), n_end: int = 15
) -> Recording:
    """~100 Hz samples with jitter, phases of random length, repeated and decreasing stamps at
    the given indices (inside phases), then `n_end` samples tagged as the end."""
    rng = np.random.default_rng(seed)
    lengths = [int(rng.integers(250, 400)) for _ in PHASES]
    tags = [p for p, n in enumerate(lengths) for _ in range(n)] + [len(PHASES)] * n_end
    parts = [phase_wrench(p, np.arange(n) / n, rng) for p, n in enumerate(lengths)]
    wrench = np.vstack([*parts, phase_wrench(2, np.ones(n_end), rng)])
    k = np.arange(len(tags))
    stamps = (T0_NS + k * STEP_NS + rng.integers(-2_000_000, 2_000_000, len(k))).tolist()
    for i in repeated:
        stamps[i] = stamps[i - 1]
    for i in decreasing:
        stamps[i] = stamps[i - 1] - 3_000_000
    log = (T0_NS + k * STEP_NS + 3_000_000 + rng.integers(0, 1_000_000, len(k))).tolist()
    return Recording(stamps, log, tags, wrench, list(repeated), list(decreasing))


def _ros1_store() -> Typestore:
    from rosbags.typesys import Stores, get_types_from_msg, get_typestore

    store = get_typestore(Stores.ROS1_NOETIC)
    store.register(get_types_from_msg(TAGGED_MSG, TAGGED))
    store.register(get_types_from_msg(DUAL_MSG, DUAL))
    return store


def _wrench(store: Typestore, w: np.ndarray) -> Any:
    V, W = store.types["geometry_msgs/msg/Vector3"], store.types["geometry_msgs/msg/Wrench"]
    return W(force=V(x=w[0], y=w[1], z=w[2]), torque=V(x=w[3], y=w[4], z=w[5]))


def _time(store: Typestore, ns: int) -> Any:
    return store.types["builtin_interfaces/msg/Time"](sec=ns // 10**9, nanosec=ns % 10**9)


def write_tagged_ros1(path: Path, rec: Recording) -> Path:
    """A ROS 1 bag of my_robot/TaggedWrench on /tag_multimodal (and a chatter topic)."""
    from rosbags.rosbag1 import Writer

    store = _ros1_store()
    Header = store.types["std_msgs/msg/Header"]
    WS, Tagged = store.types["geometry_msgs/msg/WrenchStamped"], store.types[TAGGED]
    String = store.types["std_msgs/msg/String"]
    with Writer(path) as bag:
        conn = bag.add_connection("/tag_multimodal", TAGGED, typestore=store)
        chatter = bag.add_connection("/chatter", "std_msgs/msg/String", typestore=store)
        for i, (stamp, log, tag) in enumerate(zip(rec.stamps, rec.log, rec.tags, strict=True)):
            header = Header(seq=i, stamp=_time(store, stamp), frame_id="ft")
            msg = Tagged(
                wrench_stamped=WS(header=header, wrench=_wrench(store, rec.wrench[i])), tag=tag
            )
            bag.write(conn, log, store.serialize_ros1(msg, TAGGED))
            if i % 100 == 0:
                bag.write(
                    chatter, log, store.serialize_ros1(String(data="hi"), "std_msgs/msg/String")
                )
    return path


def tagged_bag(tmp_path: Path, seed: int = 0, **kw: Any) -> tuple[Path, Recording]:
    rec = recording(seed, **kw)
    return write_tagged_ros1(tmp_path / f"run{seed}.bag", rec), rec


def import_cli(*args: str) -> int:
    return main(["bag", "import", *args])


def test_ros1_custom_type_with_an_integer_phase_map(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    from rcbht_introspection.io.bags import read_trial_bag

    bag, rec = tagged_bag(tmp_path, repeated=[40, 300, 700], decreasing=[90, 500])
    out = tmp_path / "out"
    code = import_cli(
        str(bag),
        "--out",
        str(out),
        "--wrench",
        "/tag_multimodal.wrench_stamped",
        "--phase",
        "/tag_multimodal.tag",
        "--phase-map",
        PHASE_MAP,
    )
    assert code == 0
    printed = capsys.readouterr().out
    assert "3 repeated" in printed and "2 decreasing" in printed
    trial = read_trial_bag(out / "run0.mcap")
    kept = rec.kept
    assert trial.phases == PHASES
    np.testing.assert_array_equal(trial.wrench["R"], rec.wrench[kept])
    np.testing.assert_allclose(
        trial.time, (np.asarray(rec.stamps)[kept] - rec.stamps[0]) / 1e9, atol=1e-9
    )
    starts = [(rec.stamps[rec.first(p)] - rec.stamps[0]) / 1e9 for p in range(len(PHASES))]
    np.testing.assert_allclose(trial.state_times, starts, atol=1e-9)
    report = trial.metadata["import"]
    assert isinstance(report, dict)
    arm = report["arms"]["R"]
    assert arm["repeated"] == 3 and arm["decreasing"] == 2 and arm["unset"] == 0
    assert arm["after_end"] == len(rec.tags) - rec.first(len(PHASES)) - 1
    assert arm["messages"] == len(rec.tags) and arm["kept"] == len(kept) == len(trial.time)
    assert report["stamps"] == "header" and report["time_origin_ns"] == rec.stamps[0]
    phases = report["phase_counts"]
    assert phases["end"] == "source" and phases["after_end"] == arm["after_end"]
    assert phases["repeated"] == rec.first(len(PHASES)) - len(PHASES)
    assert report["subtasks"] == list(PHASES)


def test_receive_stamps_and_the_one_wrench_topic_found_by_type(tmp_path: Path) -> None:
    from rcbht_introspection.io.bag_import import ImportOptions, read_foreign_bag
    from rcbht_introspection.io.phase_events import parse_phase_map

    bag, rec = tagged_bag(tmp_path, seed=1)
    with pytest.raises(InputError, match="no WrenchStamped/Wrench topics"):
        read_foreign_bag(bag, ImportOptions(phase="/chatter"))
    options = ImportOptions(
        wrench={"R": "/tag_multimodal.wrench_stamped"},
        phase="/tag_multimodal.tag",
        phase_map=parse_phase_map(PHASE_MAP),
        stamps="receive",
    )
    trial, report = read_foreign_bag(bag, options)
    assert report.stamps == "receive"
    np.testing.assert_allclose(
        trial.time, (np.asarray(rec.log)[rec.kept] - rec.log[0]) / 1e9, atol=1e-9
    )


def test_imported_bags_train_a_model_with_the_mapped_names(tmp_path: Path) -> None:
    from rcbht_introspection.learn.data import load_trials
    from rcbht_introspection.learn.model_file import load_model

    bags = [tagged_bag(tmp_path, seed, repeated=[100], decreasing=[600])[0] for seed in range(6)]
    out = tmp_path / "imported"
    args = [
        "--out",
        str(out),
        "--wrench",
        "R=/tag_multimodal.wrench_stamped",
        "--phase",
        "/tag_multimodal.tag",
        "--phase-map",
        PHASE_MAP,
    ]
    assert import_cli(*map(str, bags), *args) == 0
    trials = load_trials([out])
    assert len(trials) == 6
    assert all([s.subtask for s in t.samples] == list(PHASES) for t in trials)
    model_path = tmp_path / "model.rcbht"
    assert main(["train", str(out), "--out", str(model_path), "--no-live-augment"]) == 0
    model = load_model(model_path)
    assert sorted(model.classes_) == sorted(PHASES)
    assert model.task.subtasks == PHASES


def test_task_file_is_stored_and_checked(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    from rcbht_introspection.io.bags import read_trial_bag

    bag, _ = tagged_bag(tmp_path)
    task = tmp_path / "task.yaml"
    task.write_text("name: peg\nsubtasks: [reach, grasp, insert]\nend_phases: [done]\n")
    out = tmp_path / "out"
    common = [
        "--wrench",
        "/tag_multimodal.wrench_stamped",
        "--phase",
        "/tag_multimodal.tag",
        "--task",
        str(task),
    ]
    assert import_cli(str(bag), "--out", str(out), *common, "--phase-map", PHASE_MAP) == 0
    assert read_trial_bag(out / "run0.mcap").metadata["task"] == {
        "name": "peg",
        "subtasks": list(PHASES),
        "end_phases": ["done"],
    }
    other = "0=reach,1=grasp,2=press,3="
    assert import_cli(str(bag), "--out", str(tmp_path / "o2"), *common, "--phase-map", other) == 2
    err = capsys.readouterr().err
    assert "phases ['press'] are not sub-tasks of the task (reach, grasp, insert)" in err


def write_ros2(
    path: Path, rec: Recording, phase_every: int = 10, end: str | None = "finished"
) -> Path:
    """A rosbag2 (MCAP) bag: WrenchStamped on /ft/wrench, the phase name as std_msgs/String on
    /state every `phase_every` samples (a state machine's repeated publication), then `end`."""
    from rosbags.rosbag2 import StoragePlugin, Writer
    from rosbags.typesys import Stores, get_typestore

    store = get_typestore(Stores.ROS2_JAZZY)
    Header, WS = store.types["std_msgs/msg/Header"], store.types["geometry_msgs/msg/WrenchStamped"]
    String = store.types["std_msgs/msg/String"]
    with Writer(path, version=9, storage_plugin=StoragePlugin.MCAP) as bag:
        ft = bag.add_connection("/ft/wrench", WS.__msgtype__, typestore=store)
        state = bag.add_connection("/state", String.__msgtype__, typestore=store)
        last_tag = -1
        for i, (stamp, log, tag) in enumerate(zip(rec.stamps, rec.log, rec.tags, strict=True)):
            msg = WS(
                header=Header(stamp=_time(store, stamp), frame_id="ft"),
                wrench=_wrench(store, rec.wrench[i]),
            )
            bag.write(ft, log, store.serialize_cdr(msg, WS.__msgtype__))
            if tag < len(PHASES) and (tag != last_tag or i % phase_every == 0):
                bag.write(
                    state,
                    log + 500_000,
                    store.serialize_cdr(String(data=PHASES[tag]), String.__msgtype__),
                )
            elif tag == len(PHASES) and last_tag != tag and end is not None:
                bag.write(
                    state, log + 500_000, store.serialize_cdr(String(data=end), String.__msgtype__)
                )
            last_tag = tag
    return path


def test_rosbag2_with_a_string_phase_topic(tmp_path: Path) -> None:
    from rcbht_introspection.io.bag_import import ImportOptions, import_bag
    from rcbht_introspection.io.bags import read_trial_bag

    rec = recording(2, repeated=[50], n_end=10)
    bag = write_ros2(tmp_path / "ros2_run", rec)
    options = ImportOptions(phase="/state", end_phases=("finished",))  # the one wrench topic
    report = import_bag(bag, tmp_path / "out.db3", options)
    trial = read_trial_bag(tmp_path / "out.db3")
    assert trial.phases == PHASES and report.phase_counts.end == "source"
    # each name event belongs to the sample received just before it: the phase's first sample
    starts = [(rec.stamps[rec.first(p)] - rec.stamps[0]) / 1e9 for p in range(len(PHASES))]
    np.testing.assert_allclose(trial.state_times, starts, atol=1e-9)
    assert report.arms["R"].repeated == 1 and report.arms["R"].after_end == 9
    assert report.phase_counts.repeated > 0
    # without an end in the source the trial runs to the last sample and `done` is appended
    rec2 = recording(3, n_end=10)
    bag2 = write_ros2(tmp_path / "ros2_open", rec2, end=None)
    report2 = import_bag(bag2, tmp_path / "open.mcap", ImportOptions(phase="/state"))
    assert report2.phase_counts.end == "appended"
    assert report2.samples == len(rec2.tags)


def test_a_frozen_sensor_is_found_in_the_import_and_recorded(tmp_path: Path) -> None:
    """With frozen thresholds the report names a frozen stretch, as train would warn of it."""
    from rcbht_introspection.io.bag_import import ImportOptions, import_bag
    from rcbht_introspection.io.bags import read_trial_bag
    from rcbht_introspection.io.sensor_checks import trial_findings

    rec = recording(4, n_end=10)
    rec.wrench[100:200] = rec.wrench[100]  # ~1 s of one value
    bag = write_ros2(tmp_path / "stuck", rec)
    options = ImportOptions(phase="/state", end_phases=("finished",), frozen=(20, 0.5))
    report = import_bag(bag, tmp_path / "stuck.mcap", options)
    written = read_trial_bag(tmp_path / "stuck.mcap")
    assert len(report.findings) == 1 and "frozen" in report.findings[0]
    assert list(report.findings) == trial_findings(written, 20, 0.5)
    assert written.metadata["import"]["findings"] == list(report.findings)
    plain = import_bag(
        bag, tmp_path / "plain.mcap", ImportOptions(phase="/state", end_phases=("finished",))
    )
    assert plain.findings == ()  # no thresholds: not checked


def test_phase_csv_relative_and_absolute(tmp_path: Path) -> None:
    from rcbht_introspection.io.bag_import import ImportOptions, read_foreign_bag

    bag, rec = tagged_bag(tmp_path, seed=4)
    times = [0.5, 2.25, 4.0, 6.5]  # seconds from the first wrench sample; the last one ends
    names = [*PHASES, "done"]
    rel = tmp_path / "rel.csv"
    rel.write_text(
        "time,phase\n" + "".join(f"{t},{n}\n" for t, n in zip(times, names, strict=True))
    )
    absolute = tmp_path / "abs.csv"
    absolute.write_text(
        "stamp,phase\n"
        + "".join(f"{rec.stamps[0] / 1e9 + t:.9f},{n}\n" for t, n in zip(times, names, strict=True))
    )
    results = []
    for csv in (rel, absolute):
        options = ImportOptions(wrench={"R": "/tag_multimodal.wrench_stamped"}, phase_csv=csv)
        trial, report = read_foreign_bag(bag, options)
        assert trial.phases == PHASES and report.phase_counts.end == "source"
        lead = (report.time_origin_ns - rec.stamps[0]) / 1e9  # first sample at/after 0.5 s
        assert 0.5 <= lead < 0.5 + 0.013
        np.testing.assert_allclose(
            trial.state_times, [0.0, *(t - lead for t in times[1:3])], atol=1e-6
        )
        assert trial.end_time <= 6.5 - lead
        stamps = np.asarray(rec.stamps)
        assert report.arms["R"].before_first_phase == int(np.sum(stamps < rec.stamps[0] + 0.5e9))
        results.append(trial)
    np.testing.assert_array_equal(results[0].wrench["R"], results[1].wrench["R"])


def test_a_csv_folder_serves_several_bags(tmp_path: Path) -> None:
    from rcbht_introspection.io.bag_import import ImportOptions, plan_imports
    from rcbht_introspection.io.bags import read_trial_bag

    bags = [tagged_bag(tmp_path, seed)[0] for seed in (8, 9)]
    folder = tmp_path / "phases"
    folder.mkdir()
    for bag, t in zip(bags, (1.0, 2.0), strict=True):
        (folder / f"{bag.stem}.csv").write_text(f"time,phase\n0,reach\n{t},insert\n")
    options = ImportOptions(wrench={"R": "/tag_multimodal.wrench_stamped"}, phase_csv=folder)
    planned = plan_imports(bags, tmp_path / "out", options)
    done = [(p.bag, p.out, p.run()) for p in planned]
    assert [out.name for _, out, _ in done] == ["run8.mcap", "run9.mcap"]
    for (_, out, report), t in zip(done, (1.0, 2.0), strict=True):
        trial = read_trial_bag(out)
        assert trial.phases == ("reach", "insert") and report.phase_counts.end == "appended"
        assert trial.state_times[1] == pytest.approx(t, abs=1e-9)  # a CSV time is kept as given
    with pytest.raises(InputError, match=r"run8\.mcap: exists already"):
        plan_imports(bags, tmp_path / "out", options)
    with pytest.raises(InputError, match="one CSV for several bags"):
        plan_imports(bags, tmp_path / "o2", ImportOptions(phase_csv=folder / "run8.csv"))


def test_resampling_is_linear_interpolation_on_a_fixed_grid(tmp_path: Path) -> None:
    from rcbht_introspection.io.bag_import import ImportOptions, read_foreign_bag
    from rcbht_introspection.io.phase_events import parse_phase_map

    rec = recording(5, repeated=[30], decreasing=[400])
    seconds = (np.asarray(rec.stamps) - T0_NS) / 1e9
    rec.wrench = np.column_stack(
        [2 * seconds + 1, -seconds, 0 * seconds + 3, seconds**0, seconds, 5 - seconds]
    )
    bag = write_tagged_ros1(tmp_path / "ramp.bag", rec)
    options = ImportOptions(
        wrench={"R": "/tag_multimodal.wrench_stamped"},
        phase="/tag_multimodal.tag",
        phase_map=parse_phase_map(PHASE_MAP),
        rate_hz=50.0,
    )
    trial, report = read_foreign_bag(bag, options)
    np.testing.assert_allclose(np.diff(trial.time), 0.02, atol=1e-9)
    t = (report.time_origin_ns - T0_NS) / 1e9 + trial.time
    w = trial.wrench["R"]
    np.testing.assert_allclose(w[:, 0], 2 * t + 1, atol=1e-9)
    np.testing.assert_allclose(w[:, 5], 5 - t, atol=1e-9)
    assert report.rate_hz == 50.0 and report.samples == len(trial.time)
    assert report.arms["R"].repeated == 1 and report.arms["R"].decreasing == 1
    assert len(trial.time) == pytest.approx(report.arms["R"].kept / 2, abs=2)


def write_dual_ros1(path: Path, rec: Recording, left_offset_ns: int = 0) -> Path:
    """Two arms in one my_robot/DualArm message (header, left/right Wrench, string phase); with
    `left_offset_ns`, the left arm also on its own topic /left (my_robot/DualArm, shifted)."""
    from rosbags.rosbag1 import Writer

    store = _ros1_store()
    Header, Dual = store.types["std_msgs/msg/Header"], store.types[DUAL]
    with Writer(path) as bag:
        dual = bag.add_connection("/dual", DUAL, typestore=store)
        left = bag.add_connection("/left", DUAL, typestore=store) if left_offset_ns else None
        for i, (stamp, log, tag) in enumerate(zip(rec.stamps, rec.log, rec.tags, strict=True)):
            name = PHASES[tag] if tag < len(PHASES) else "done"
            msg = Dual(
                header=Header(seq=i, stamp=_time(store, stamp), frame_id=""),
                left=_wrench(store, -rec.wrench[i]),
                right=_wrench(store, rec.wrench[i]),
                phase=name,
            )
            bag.write(dual, log, store.serialize_ros1(msg, DUAL))
            if left is not None:
                shifted = Dual(
                    header=Header(seq=i, stamp=_time(store, stamp + left_offset_ns), frame_id=""),
                    left=_wrench(store, -rec.wrench[i]),
                    right=_wrench(store, rec.wrench[i]),
                    phase=name,
                )
                bag.write(left, log + left_offset_ns, store.serialize_ros1(shifted, DUAL))
    return path


def test_two_arms_of_one_message_and_of_two_topics(tmp_path: Path) -> None:
    from rcbht_introspection.io.bag_import import ImportOptions, read_foreign_bag

    rec = recording(6, n_end=5)
    bag = write_dual_ros1(tmp_path / "dual.bag", rec, left_offset_ns=3_000_000)
    options = ImportOptions(wrench={"L": "/dual.left", "R": "/dual.right"}, phase="/dual.phase")
    trial, report = read_foreign_bag(bag, options)
    assert report.stamps == "header"  # the enclosing message's header
    assert trial.arms == ("L", "R") and trial.phases == PHASES
    np.testing.assert_array_equal(trial.wrench["L"], -trial.wrench["R"])
    np.testing.assert_array_equal(trial.wrench["R"], rec.wrench[rec.kept])
    two_topics = ImportOptions(wrench={"R": "/dual.right", "L": "/left.left"}, phase="/dual.phase")
    with pytest.raises(InputError, match="different stamps: give --rate"):
        read_foreign_bag(bag, two_topics)
    trial, report = read_foreign_bag(bag, replace(two_topics, rate_hz=100.0))
    assert trial.arms == ("L", "R") and report.samples == len(trial.time)
    np.testing.assert_allclose(np.diff(trial.time), 0.01, atol=1e-9)
    # the grid starts where both arms have samples: the left arm's first, 3 ms after the right's
    assert report.time_origin_ns == rec.stamps[0] + 3_000_000


TAG = f"--phase /tag_multimodal.tag --phase-map {PHASE_MAP}"
WS = "--wrench /tag_multimodal.wrench_stamped"
BAD = [  # (arguments after BAG --out DIR, the error's text)
    (f"--wrench /nope {TAG}",
     "field /nope: no such topic; the bag has /chatter (std_msgs/msg/String), /tag_multimodal (my_robot/msg/TaggedWrench)"),
    (f"--wrench /tag_multimodal.wrench_stampd.wrench {TAG}",
     "no field 'wrench_stampd' in my_robot/msg/TaggedWrench (fields: wrench_stamped, tag)"),
    (f"--wrench /tag_multimodal.wrench_stamped.wrench.forc {TAG}",
     "no field 'forc' in geometry_msgs/msg/Wrench (fields: force, torque)"),
    (f"--wrench /tag_multimodal.tag {TAG}",
     "field /tag_multimodal.tag: is int32, not a WrenchStamped or Wrench"),
    (f"{WS} --phase /tag_multimodal.tag.value", "tag is int32, it has no field 'value'"),
    (f"{WS} --phase /tag_multimodal.tag", "is int32: give --phase-map"),
    (f"{WS} --phase /tag_multimodal.tag --phase-map 0=reach,1=grasp,3=",
     "field /tag_multimodal.tag: value 2 has no name in --phase-map (named: 0, 1, 3)"),
    (f"{WS} --phase /tag_multimodal.tag --phase-map 0=reach,one=grasp",
     "field --phase-map: 'one=grasp' is not VALUE=NAME"),
    (f"{WS} --phase /tag_multimodal.tag --phase-map 0=reach,1=grasp,2=done,3= --end-phase finish",
     "phase 'done' would end the trial in the written bag"),
    (f"{WS} --phase /chatter --phase-map {PHASE_MAP}",
     "field /chatter: is string; --phase-map needs an integer field"),
]  # fmt: skip


@pytest.mark.parametrize(("args", "message"), BAD)
def test_bad_input_is_one_named_line(
    tmp_path: Path, capsys: pytest.CaptureFixture[str], args: str, message: str
) -> None:
    bag, _ = tagged_bag(tmp_path, n_end=3)
    assert import_cli(str(bag), "--out", str(tmp_path / "out"), *args.split()) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and message in err
    if "--phase-map:" not in message:
        assert str(bag) in err
    assert not (tmp_path / "out" / "run0.mcap").exists()


def test_bad_phase_csv_and_bad_bag(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    bag, _ = tagged_bag(tmp_path, n_end=3)
    csv = tmp_path / "p.csv"
    csv.write_text("seconds,phase\n0.1,reach\n")
    args = ["--out", str(tmp_path / "out"), "--wrench", "/tag_multimodal.wrench_stamped"]
    assert import_cli(str(bag), *args, "--phase-csv", str(csv)) == 2
    assert f"{csv}, line 1: header must be 'time,phase' or 'stamp,phase'" in capsys.readouterr().err
    csv.write_text("time,phase\n0.1,reach\n0.05,grasp\n")
    assert import_cli(str(bag), *args, "--phase-csv", str(csv)) == 2
    assert f"{csv}, line 3, field time: 0.05 comes before" in capsys.readouterr().err
    text = tmp_path / "notes.txt"
    text.write_text("not a bag")
    assert import_cli(str(text), *args, "--phase", "/chatter") == 2
    assert "not a ROS 1 bag (.bag) or a rosbag2 bag" in capsys.readouterr().err
    broken = tmp_path / "broken.bag"
    broken.write_bytes(b"#ROSBAG V2.0\n" + b"\x00" * 64)
    assert import_cli(str(broken), *args, "--phase", "/chatter") == 2
    assert f"{broken}: cannot read bag" in capsys.readouterr().err


def test_a_wrench_without_header_takes_receive_times(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    """geometry_msgs/Wrench on its own topic: `auto` uses the receive times, `header` is an error
    (a Wrench inside a WrenchStamped takes that header: the dual-arm test)."""
    from rosbags.rosbag2 import StoragePlugin, Writer
    from rosbags.typesys import Stores, get_typestore

    from rcbht_introspection.io.bag_import import ImportOptions, read_foreign_bag

    rec = recording(7, n_end=4)
    store = get_typestore(Stores.ROS2_JAZZY)
    String = store.types["std_msgs/msg/String"]
    path = tmp_path / "raw.mcap"
    with Writer(tmp_path / "raw", version=9, storage_plugin=StoragePlugin.MCAP) as bag:
        ft = bag.add_connection("/raw_wrench", "geometry_msgs/msg/Wrench", typestore=store)
        state = bag.add_connection("/state", String.__msgtype__, typestore=store)
        for i, (log, tag) in enumerate(zip(rec.log, rec.tags, strict=True)):
            raw = store.serialize_cdr(_wrench(store, rec.wrench[i]), "geometry_msgs/msg/Wrench")
            bag.write(ft, log, raw)
            if i == 0 or tag != rec.tags[i - 1]:
                name = PHASES[tag] if tag < len(PHASES) else "done"
                bag.write(
                    state, log + 1, store.serialize_cdr(String(data=name), String.__msgtype__)
                )
    next((tmp_path / "raw").glob("*.mcap")).rename(path)  # a single storage file
    trial, report = read_foreign_bag(path, ImportOptions(phase="/state"))
    assert report.stamps == "receive" and trial.phases == PHASES
    np.testing.assert_allclose(
        trial.time, (np.asarray(rec.log[: len(trial.time)]) - rec.log[0]) / 1e9, atol=1e-9
    )
    args = ["--out", str(tmp_path / "out"), "--stamps", "header", "--phase", "/state"]
    assert import_cli(str(path), *args) == 2
    err = capsys.readouterr().err
    assert (
        f"{path}, field /raw_wrench: no header to take a stamp from (use --stamps receive)" in err
    )


IDLE = 9
OUT_MAP = f"{IDLE}=-,0=reach,1=grasp,2=insert"


def idle_recording(seed: int, n_before: int = 40, n_after: int = 25) -> Recording:
    """recording(seed) with the robot idle (tag IDLE, outside the task) for its first `n_before`
    samples and its last `n_after`, as a state machine's idle state before and after the task."""
    rec = recording(seed, n_end=n_after)
    tags = [IDLE if t == len(PHASES) else t for t in rec.tags]
    tags[:n_before] = [IDLE] * n_before
    return replace(rec, tags=tags)


def test_phases_outside_the_task_are_cut_and_counted(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    """`--phase-map 9=-`: the idle before the first task phase and after the last one is cut and
    counted; idle is neither a sub-task nor the end phase, so the trial ends where it begins."""
    from rcbht_introspection.io.bags import read_trial_bag

    rec = idle_recording(11)
    bag = write_tagged_ros1(tmp_path / "idle.bag", rec)
    out = tmp_path / "out"
    assert import_cli(str(bag), "--out", str(out), *WS.split(), *TAG.split()[:2],
                      "--phase-map", OUT_MAP) == 0  # fmt: skip
    printed = capsys.readouterr().out
    assert "end out_of_task" in printed and "40 outside the task before the first phase" in printed
    trial = read_trial_bag(out / "idle.mcap")
    assert trial.phases == PHASES
    first, end = rec.first(0), len(rec.tags) - 25  # the first idle sample after the task ends it
    np.testing.assert_array_equal(trial.wrench["R"], rec.wrench[first : end + 1])
    report = trial.metadata["import"]
    assert isinstance(report, dict) and report["time_origin_ns"] == rec.stamps[first]
    assert report["arms"]["R"]["before_first_phase"] == 40
    assert report["arms"]["R"]["after_end"] == 24
    assert report["phase_counts"] == {
        "events": len(rec.tags),
        "repeated": end - first - len(PHASES),
        "empty": 0,
        "after_end": 24,
        "end": "out_of_task",
        "before_first_phase": 40,
        "resumed": 0,
    }
    assert report["subtasks"] == list(PHASES) and report["findings"] == []


def test_idle_as_the_end_phase_names_the_way_out(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    """Idle at the start mapped to the end phase leaves no sub-task: the error says how to name a
    value outside the task. A task that resumes after idle ends at the idle, with a warning."""
    rec = idle_recording(12)
    bag = write_tagged_ros1(tmp_path / "idle.bag", rec)
    args = [*WS.split(), *TAG.split()[:2]]
    as_end = f"{IDLE}=,0=reach,1=grasp,2=insert"
    assert import_cli(str(bag), "--out", str(tmp_path / "o1"), *args, "--phase-map", as_end) == 2
    err = capsys.readouterr().err
    assert "no sub-task phase before the end phase" in err and "--phase-map 0=-" in err
    pause = rec.first(1) + 50
    rec.tags[pause : pause + 30] = [IDLE] * 30  # idle inside grasp, then grasp and insert go on
    bag = write_tagged_ros1(tmp_path / "pause.bag", rec)
    out = tmp_path / "o2"
    assert import_cli(str(bag), "--out", str(out), *args, "--phase-map", OUT_MAP) == 0
    err = capsys.readouterr().err
    resumed = sum(t != IDLE for t in rec.tags[pause:])
    assert f"warning: pause.mcap: {resumed} task phase events after the trial's end" in err
    from rcbht_introspection.io.bags import read_trial_bag

    trial = read_trial_bag(out / "pause.mcap")
    assert trial.phases == ("reach", "grasp") and len(trial.time) == pause - rec.first(0) + 1
    report = trial.metadata["import"]
    assert isinstance(report, dict) and report["phase_counts"]["resumed"] == resumed


def test_a_phase_csv_and_string_names_outside_the_task(tmp_path: Path) -> None:
    """A CSV row `-` and a name given in out_of_task (`idle`) are both outside the task."""
    from rcbht_introspection.io.bag_import import ImportOptions, read_foreign_bag

    bag, _ = tagged_bag(tmp_path, seed=13)
    csv = tmp_path / "p.csv"
    csv.write_text("time,phase\n0,-\n0.5,reach\n2.25,grasp\n4.0,insert\n6.5,idle\n7.0,idle\n")
    options = ImportOptions(
        wrench={"R": "/tag_multimodal.wrench_stamped"}, phase_csv=csv, out_of_task=("idle",)
    )
    trial, report = read_foreign_bag(bag, options)
    assert trial.phases == PHASES and trial.end_time <= 6.0 + 0.013
    counts = report.phase_counts
    assert (counts.end, counts.before_first_phase, counts.after_end) == ("out_of_task", 1, 1)
    with pytest.raises(InputError, match="idle' cannot end the trial and be outside the task"):
        read_foreign_bag(bag, replace(options, end_phases=("idle",)))


BAXTER = HIRO.parent / "baxter_pick_and_place"
BAXTER_MAP = "0=-,1=approach,2=grasp,5=lift,3=transport,4=place"
"""The Baxter state machine's tags (birl_baxter_tasks): 1 to the hover pose above the object, 2
down and close the gripper, 5 back up, 3 to the hover pose above the target, 4 down, open, up."""


@pytest.mark.shared_data
def test_the_baxter_bags_import_with_one_command_line(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    """The real Baxter ROS 1 bags (idle tag 0 before and after the task): one command line, no
    CSV, imports all 19; `rcbht evaluate` on session_a then learns the five sub-tasks."""
    import json

    require(BAXTER.is_dir(), f"Baxter bags not found at {BAXTER}")
    bags = sorted(BAXTER.glob("session_a/*.bag")) + sorted(BAXTER.glob("other_sessions/*.bag"))
    assert len(bags) == 19
    out = tmp_path / "baxter"
    assert import_cli(*map(str, bags), "--out", str(out), *WS.split(), "--phase",
                      "/tag_multimodal.tag", "--phase-map", BAXTER_MAP) == 0  # fmt: skip
    printed = capsys.readouterr().out
    assert (
        printed.count("phases approach > grasp > lift > transport > place (end out_of_task") == 19
    )
    assert len(list(out.glob("*.mcap"))) == 19
    session_a = sorted(out.glob("s??.mcap"))
    result = tmp_path / "eval.json"
    assert main(["evaluate", *map(str, session_a), "--permutations", "2", "--json", str(result),
                 "--no-progress", "--no-peers"]) == 0  # fmt: skip
    curve = json.loads(result.read_text())
    assert curve["task"]["subtasks"] == ["approach", "grasp", "lift", "transport", "place"]
    assert curve["n_trials"] == 15
    assert curve["steady_state_accuracy"]["mean"] >= 0.95
    assert curve["duration_baseline"]["mean"] < curve["steady_state_accuracy"]["mean"] - 0.2
