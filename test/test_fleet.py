"""Every offline command of many inputs on joblib workers and on a Dask cluster: `--jobs 2` (and
`--scheduler` on a loopback LocalCluster) writes what `--jobs 1` writes; the option's errors are
one line (rcbht_introspection/fleet.py)."""

from __future__ import annotations

import json
from collections.abc import Iterator
from pathlib import Path

import pytest
from conftest import SIM_SUCCESS

from rcbht_introspection.cli import main


def tree(root: Path) -> dict[str, bytes]:
    """Every file under `root` by its relative path, with its bytes."""
    return {
        str(p.relative_to(root)): p.read_bytes() for p in sorted(root.rglob("*")) if p.is_file()
    }


@pytest.fixture(scope="module")
def cluster() -> Iterator[str]:
    """A dask.distributed LocalCluster on loopback only: its scheduler's address."""
    from dask.distributed import LocalCluster

    with LocalCluster(
        n_workers=2,
        threads_per_worker=1,
        processes=True,
        host="127.0.0.1",
        dashboard_address=None,
    ) as local:
        yield local.scheduler_address


def test_sim_writes_the_same_set_whatever_the_workers(tmp_path: Path, cluster: str) -> None:
    args = ["sim", "--trials", "3", "--seed", "4", "--sessions", "2", "--progress", "off"]
    outs = {}
    for name, extra in (("one", []), ("two", ["--jobs", "2"]), ("dask", ["--scheduler", cluster])):
        outs[name] = tmp_path / name
        assert main([*args, "--out", str(outs[name]), *extra]) == 0
    one = tree(outs["one"])
    assert len([k for k in one if k.endswith("meta.json")]) == 4  # 3 trials + sim_meta.json
    assert tree(outs["two"]) == one
    assert tree(outs["dask"]) == one


@pytest.mark.parametrize("jobs", ["0", "-2"])
def test_a_bad_job_count_is_one_line(
    jobs: str, sim_data: Path, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    assert main(["label", str(sim_data / SIM_SUCCESS), "--out", str(tmp_path), "--jobs", jobs]) == 2
    assert f"--jobs: must be a positive count or -1 (one per core), not {jobs}" in (
        capsys.readouterr().err
    )


def _json(path: Path) -> object:
    return json.loads(path.read_text())


TIMINGS = ("fit_seconds", "predict_ms")
"""Measured times of the evaluation JSON: the only figures that differ between two runs."""


def _untimed(value: object) -> object:
    """A JSON value without its measured times."""
    if isinstance(value, dict):
        return {k: _untimed(v) for k, v in value.items() if k not in TIMINGS}
    if isinstance(value, list):
        return [_untimed(v) for v in value]
    return value


def test_evaluate_gives_the_same_curve_whatever_the_workers(
    sim_data: Path, tmp_path: Path, cluster: str
) -> None:
    args = ["evaluate", str(sim_data / SIM_SUCCESS), "--permutations", "2", "--no-progress"]
    args += ["--trials", "6", "--validation-trials", "2", "--no-peers", "--json"]
    runs = {}
    for name, extra in (("one", []), ("two", ["--jobs", "2"]), ("dask", ["--scheduler", cluster])):
        assert main([*args, str(tmp_path / f"{name}.json"), *extra]) == 0
        runs[name] = _untimed(_json(tmp_path / f"{name}.json"))
    one = runs["one"]
    assert isinstance(one, dict) and len(one["curve"]) >= 2 and one["trial_splits"]["n"] == 2
    assert runs["two"] == one
    assert runs["dask"] == one


def _set_with_a_bad_trial(sim_data: Path, root: Path) -> Path:
    """Three simulated trial folders and, sorted first among them, one with a malformed table."""
    import shutil

    for folder in sorted((sim_data / SIM_SUCCESS).iterdir())[:3]:
        shutil.copytree(folder, root / folder.name)
    (root / "A-BAD").mkdir()
    (root / "A-BAD" / "R_Torques.dat").write_text("0.0 1 2 3\nnot a number\n")
    return root


def test_label_writes_the_same_words_and_leaves_a_bad_trial_out(
    sim_data: Path, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    data = _set_with_a_bad_trial(sim_data, tmp_path / "set")
    for name, extra in (("one", []), ("two", ["--jobs", "2"])):
        assert main(["label", str(data), "--out", str(tmp_path / name), *extra]) == 0
        out, err = capsys.readouterr()
        assert "labelled 3 trial(s)" in out
        assert "rcbht label: left out: " in err and "A-BAD" in err
        assert "rcbht label: 1 of 4 inputs bad, left out (" in err
    one = tree(tmp_path / "one")
    assert len({k.split("/")[0] for k in one}) == 3
    assert tree(tmp_path / "two") == one
    assert main(["label", str(data), "--out", str(tmp_path / "strict"), "--strict"]) == 2
    assert tree(tmp_path / "strict") == one  # the good ones are written all the same


def _frozen_and_good_bags(root: Path) -> list[Path]:
    """A ROS 1 bag whose sensor froze (every message repeats the first wrench sample, stamp and
    values: no phase keeps a sample), then three good ones (test_bag_import's recordings)."""
    from test_bag_import import recording, write_tagged_ros1

    root.mkdir()
    frozen = recording(9)
    frozen.stamps = [frozen.stamps[0]] * len(frozen.stamps)
    frozen.wrench[:] = frozen.wrench[0]
    bags = [write_tagged_ros1(root / "a_frozen.bag", frozen)]
    return bags + [write_tagged_ros1(root / f"run{s}.bag", recording(s)) for s in (1, 2, 3)]


def test_bag_import_of_a_frozen_bag_first_imports_the_good_ones(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    from conftest import require
    from ros_support import have
    from test_bag_import import PHASE_MAP

    require(have("rosbags"), "rosbags not installed")
    bags = [str(b) for b in _frozen_and_good_bags(tmp_path / "in")]
    args = ["bag", "import", *bags, "--wrench", "/tag_multimodal.wrench_stamped", "--phase"]
    args += ["/tag_multimodal.tag", "--phase-map", PHASE_MAP]
    outs = {}
    for name, extra in (("one", []), ("two", ["--jobs", "2"])):
        outs[name] = tmp_path / name
        report = tmp_path / f"{name}.json"
        assert main([*args, "--out", str(outs[name]), "--json", str(report), *extra]) == 0
        out, err = capsys.readouterr()
        assert "imported 3 of 4 bag(s)" in out
        left = [line for line in err.splitlines() if "left out: " in line]
        assert len(left) == 1 and bags[0] in left[0] and left[0].endswith("no phase has samples")
        assert "1 of 4 inputs bad, left out (" in err
        bad = _json(report)
        assert isinstance(bad, dict) and bad["bad_inputs"]["count"] == 1
        assert bad["bad_inputs"]["inputs"][0]["input"] == bags[0]
    assert sorted(tree(outs["one"])) == ["run1.mcap", "run2.mcap", "run3.mcap"]
    assert tree(outs["two"]) == tree(outs["one"])
    assert main([*args, "--out", str(tmp_path / "strict"), "--strict"]) == 2
    assert len(tree(tmp_path / "strict")) == 3  # written all the same
    capsys.readouterr()
    assert (
        main(["bag", "import", bags[0], *args[2 + len(bags) :], "--out", str(tmp_path / "none")])
        == 2
    )
    assert capsys.readouterr().err.count("\n") == 1  # nothing done: one line, as ever


def test_calibrate_measures_the_same_profile_and_names_a_bad_trial(
    sim_data: Path, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    data = _set_with_a_bad_trial(sim_data, tmp_path / "set")
    written = {}
    for name, extra in (("one", []), ("two", ["--jobs", "2"])):
        out, report = tmp_path / name / "robot.yaml", tmp_path / name / "report.json"
        args = ["calibrate", str(data), "--out", str(out), "--report", str(report)]
        assert main([*args, *extra]) == 0
        assert "A-BAD" in capsys.readouterr().err
        result = _json(report)
        assert isinstance(result, dict) and result["bad_inputs"]["count"] == 1
        assert len(result["inputs"]) == 3
        del result["out"]  # the only difference: where each run wrote
        written[name] = {"profile": out.read_bytes(), "report": result}
    assert written["two"] == written["one"]
    strict = ["calibrate", str(data), "--out", str(tmp_path / "s.yaml"), "--strict"]
    assert main(strict) == 2 and (tmp_path / "s.yaml").is_file()


def test_audit_reports_the_same_whatever_the_workers(
    sim_data: Path, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    data = _set_with_a_bad_trial(sim_data, tmp_path / "set")
    printed, reports = {}, {}
    for name, extra in (("one", []), ("two", ["--jobs", "2"])):
        report = tmp_path / f"{name}.json"
        args = ["audit", str(data), "--permutations", "199", "--json", str(report)]
        assert main([*args, *extra]) == 0
        printed[name] = capsys.readouterr().out.replace(str(report), "OUT")
        reports[name] = _json(report)
    assert "3 trial(s), 1 unreadable" in printed["one"]
    assert printed["two"] == printed["one"]
    assert reports["two"] == reports["one"]
    one = reports["one"]
    assert isinstance(one, dict) and one["bad_inputs"]["count"] == 1
    assert main(["audit", str(data), "--permutations", "199", "--strict"]) == 2


def test_a_warm_sample_cache_stays_warm_on_a_worker(sim_data: Path) -> None:
    """The curve's permutations ship one encoding cache to the workers: unpickled with its
    samples, it answers from what it holds instead of encoding again."""
    import pickle

    from rcbht_introspection.grammar.encoding.cache import SampleCache
    from rcbht_introspection.learn.data import load_trials

    sample = load_trials([sim_data / SIM_SUCCESS])[0].samples[0]
    cache = SampleCache()
    assert cache.get(sample, "key", lambda: 42) == 42
    copied_cache, copied_sample = pickle.loads(pickle.dumps((cache, sample)))
    assert copied_sample is not sample

    def encode_again() -> int:
        raise AssertionError("encoded again")

    assert copied_cache.get(copied_sample, "key", encode_again) == 42


def test_train_evaluate_and_verify_leave_an_unreadable_trial_out(
    sim_data: Path, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    """The fitting commands read every trial first: a bad one is named and counted in their JSON,
    the others are used; under --strict it stops the run with exit code 2."""
    import shutil

    data = _set_with_a_bad_trial(sim_data, tmp_path / "set")
    for folder in sorted(p for p in (sim_data / SIM_SUCCESS).iterdir() if p.is_dir())[3:]:
        shutil.copytree(folder, data / folder.name)
    model = tmp_path / "m.rcbht"
    train = ["train", str(data), "--out", str(model), "--no-live-augment"]
    assert main(train) == 0 and model.is_file()
    out, err = capsys.readouterr()
    assert "from 8 trials" in out and "rcbht train: 1 of 9 inputs bad, left out (" in err
    assert main([*train, "--strict"]) == 2
    assert capsys.readouterr().err.count("\n") == 1  # the bad trial's own one-line error
    curve = tmp_path / "curve.json"
    evaluate = ["evaluate", str(data), "--permutations", "1", "--no-peers", "--json", str(curve)]
    assert main(evaluate) == 0
    result = _json(curve)
    assert isinstance(result, dict) and result["n_trials"] == 8
    assert (
        result["bad_inputs"]["count"] == 1 and "A-BAD" in result["bad_inputs"]["inputs"][0]["input"]
    )
    assert "A-BAD" in capsys.readouterr().err
    verifier = tmp_path / "v.rcbht"
    assert main(["verify-train", str(data), "--out", str(verifier)]) == 0
    assert verifier.is_file() and "verify-train: 1 of 9 inputs bad" in capsys.readouterr().err


def test_verify_eval_train_set_with_failures_fits_the_peers(tmp_path: Path) -> None:
    """With failures in --train, the anchors' classifiers are fitted on them (their trials are
    keyed train:<name>, not by their names) and name the test set's failures."""
    import shutil

    from rcbht_introspection.sim.dataset import write_dataset

    folders = write_dataset(tmp_path / "sim", 10, seed=3, failures=True)
    for i, folder in enumerate(folders):
        shutil.copytree(folder, tmp_path / ("train" if i < 7 else "test") / folder.name)
    out = tmp_path / "eval.json"
    args = ["verify-eval", str(tmp_path / "test"), "--train", str(tmp_path / "train")]
    assert main([*args, "--json", str(out)]) == 0
    result = _json(out)
    assert isinstance(result, dict)
    named = {
        r["method"]: r["class_given_onset"]
        for r in result["records"]
        if r["outcome"] != "success" and r["method"] in ("hmm", "minirocket")
    }
    assert set(named) == {"hmm", "minirocket"} and all(named.values())


def test_the_curve_steps_are_dealt_once_each_and_evenly() -> None:
    """Every (permutation, step) lands in exactly one worker's hand; the hands' estimated
    costs differ by at most the costliest unit (the greedy rule's bound)."""
    from types import SimpleNamespace

    from rcbht_introspection.learn.evaluate import LAST_STEP_WEIGHT, _deal

    steps = list(range(1, 37))
    for permutations, workers in ((5, 2), (3, 4), (1, 8), (20, 3)):
        run = SimpleNamespace(
            plan=SimpleNamespace(steps=steps), protocol=SimpleNamespace(permutations=permutations)
        )
        hands = _deal(run, workers)  # type: ignore[arg-type]
        dealt = [(p, j) for hand in hands for p, js in hand.items() for j in js]
        assert sorted(dealt) == [(p, j) for p in range(permutations) for j in range(36)]
        cost = [
            sum(steps[j] * (LAST_STEP_WEIGHT if j == 35 else 1) for js in h.values() for j in js)
            for h in hands
        ]
        assert max(cost) - min(cost) <= 36 * LAST_STEP_WEIGHT
