"""The peer baselines (rcbht_introspection/peers/): the successor framework's HMM detector and
classifier, and MiniRocket with a ridge classifier, on synthetic wrench-like series made here.

aeon's MiniRocket is compiled by numba on its first call after `make setup` (about 20 s on
2 cores); numba caches it beside aeon's sources in .venv, so later runs load it at once.
"""

from __future__ import annotations

import ast
import subprocess
import sys
from importlib.metadata import version
from pathlib import Path

import numpy as np
import pytest
from sklearn.base import clone
from sklearn.model_selection import StratifiedKFold, cross_val_score

pytest.importorskip("hmmlearn")
pytest.importorskip("aeon")

from rcbht_introspection.peers.hmm import (
    HMMClassifier,
    HMMDetector,
)
from rcbht_introspection.peers.minirocket import MiniRocketClassifier
from rcbht_introspection.summaries.windows import resample

REPO = Path(__file__).resolve().parents[1]
PACKAGE = REPO / "rcbht_introspection"
NO_PEERS_AT_IMPORT = ("taxonomy", "live", "learn", "verify", "nodes")
SCALE = np.array([10.0, 10.0, 10.0, 0.1, 0.1, 0.1])
"""Forces in N, torques in N m: two orders of magnitude apart, as on a real wrist sensor."""


# ------------------------------------------------------------------ synthetic data
def _nominal(rng: np.random.Generator, phase: int, length: int) -> np.ndarray:
    """A (T, 6) wrench of a successful sub-task: a smooth pattern per sub-task plus noise."""
    t = np.linspace(0.0, 1.0, length)
    shape = np.stack(
        [
            np.sin(np.pi * t * (1 + phase)),
            t**2 - phase * t,
            np.cos(np.pi * t),
            np.sin(2 * np.pi * t + phase),
            t,
            1 - t,
        ],
        axis=1,
    )
    return (shape + rng.normal(scale=0.08, size=shape.shape)) * SCALE


def _failure(rng: np.random.Generator, kind: int, length: int) -> np.ndarray:
    """A (T, 6) evidence window of failure class `kind`: each class bends other axes."""
    t = np.linspace(0.0, 1.0, length)
    window = rng.normal(scale=0.15, size=(length, 6))
    amplitude = rng.uniform(0.8, 1.2)
    if kind == 0:  # a force rise along z, then a plateau
        window[:, 2] += amplitude * np.minimum(1.0, 3 * t)
    elif kind == 1:  # an oscillation in x and its torque about y
        window[:, 0] += amplitude * np.sin(4 * np.pi * t)
        window[:, 4] += amplitude * np.sin(4 * np.pi * t)
    else:  # a torque about z growing with time
        window[:, 5] += amplitude * 2 * t
    return window * SCALE


def _failures(seed: int, per_class: int) -> tuple[list[np.ndarray], np.ndarray]:
    rng = np.random.default_rng(seed)
    labels = np.repeat(np.array(["jam", "slip", "twist"]), per_class)
    windows = [
        _failure(rng, ["jam", "slip", "twist"].index(str(c)), int(rng.integers(15, 50)))
        for c in labels
    ]
    return windows, labels


def _cv_accuracy(estimator: object, windows: list[np.ndarray], labels: np.ndarray) -> float:
    folds = StratifiedKFold(n_splits=3, shuffle=True, random_state=0)
    return float(np.mean(cross_val_score(estimator, windows, labels, cv=folds)))


# ------------------------------------------------------------------ the package's boundary
def _package_of(path: Path) -> str:
    return ".".join(path.relative_to(REPO).with_suffix("").parts[:-1])


def _is_type_checking_block(node: ast.AST) -> bool:
    """`if TYPE_CHECKING:` holds imports for the type checker only; they never run."""
    if not isinstance(node, ast.If):
        return False
    test = node.test
    return (isinstance(test, ast.Name) and test.id == "TYPE_CHECKING") or (
        isinstance(test, ast.Attribute) and test.attr == "TYPE_CHECKING"
    )


def _module_level_imports_of(source: str, package: str) -> set[str]:
    """Absolute names imported outside functions and `if TYPE_CHECKING:` by `source`."""

    names: set[str] = set()
    todo: list[ast.AST] = [ast.parse(source)]
    while todo:
        node = todo.pop()
        for child in ast.iter_child_nodes(node):
            if isinstance(child, (ast.FunctionDef, ast.AsyncFunctionDef, ast.Lambda)):
                continue
            if _is_type_checking_block(child):
                continue
            if isinstance(child, ast.Import):
                names.update(alias.name for alias in child.names)
            elif isinstance(child, ast.ImportFrom):
                base = package.rsplit(".", child.level - 1)[0] if child.level else ""
                module = ".".join(p for p in (base, child.module or "") if p)
                names.update(f"{module}.{alias.name}" for alias in child.names)
            todo.append(child)
    return names


def _module_level_imports(path: Path, package: str) -> set[str]:
    """What importing the module at `path` of `package` imports."""
    return _module_level_imports_of(path.read_text(), package)


def test_the_import_scan_sees_module_level_imports_and_skips_type_checking_blocks() -> None:
    source = (
        "from typing import TYPE_CHECKING\n"
        "from .peers import a\n"
        "if TYPE_CHECKING:\n    from aeon import b\n"
        "if True:\n    import hmmlearn\n"
        "def f():\n    import numba\n"
    )
    names = _module_level_imports_of(source, "rcbht_introspection")
    assert names == {"typing.TYPE_CHECKING", "rcbht_introspection.peers.a", "hmmlearn"}


@pytest.mark.parametrize("subpackage", NO_PEERS_AT_IMPORT)
def test_the_core_and_the_nodes_do_not_import_the_peers_at_import_time(subpackage: str) -> None:
    for path in sorted((PACKAGE / subpackage).rglob("*.py")):
        imported = _module_level_imports(path, _package_of(path))
        peers = {n for n in imported if n.startswith("rcbht_introspection.peers")}
        libraries = {n for n in imported if n.split(".")[0] in ("hmmlearn", "aeon", "numba")}
        assert not peers | libraries, (
            f"{path.relative_to(REPO)} imports {sorted(peers | libraries)}"
        )


def test_the_import_scan_sees_relative_and_nested_imports(tmp_path: Path) -> None:
    module = tmp_path / "probe.py"
    text = "from ..peers import hmm\nif True:\n    import aeon\ndef f():\n    import hmmlearn\n"
    module.write_text(text)
    found = _module_level_imports(module, "rcbht_introspection.verify")
    assert {"rcbht_introspection.peers.hmm", "aeon"} <= found
    assert "hmmlearn" not in found


def test_the_peers_package_imports_neither_library() -> None:
    code = (
        "import sys, rcbht_introspection.peers\n"
        "print(sorted(m for m in ('hmmlearn', 'aeon', 'numba') if m in sys.modules))\n"
    )
    out = subprocess.run(
        [sys.executable, "-c", code], capture_output=True, text=True, check=True, cwd=REPO
    )
    assert out.stdout.strip() == "[]", out.stdout


def _setup_keyword(name: str) -> dict[str, list[str]]:
    """The literal value of one keyword of the setup() call in setup.py."""
    tree = ast.parse((REPO / "setup.py").read_text())
    for node in ast.walk(tree):
        if isinstance(node, ast.keyword) and node.arg == name:
            value: dict[str, list[str]] = ast.literal_eval(node.value)
            return value
    return {}


def test_the_peer_pins_are_exact_installed_and_match_the_extra() -> None:
    pins = {}
    for line in (REPO / "requirements-peers.txt").read_text().splitlines():
        line = line.split("#")[0].strip()
        if line:
            name, sep, pinned = line.partition("==")
            assert sep and pinned, f"not pinned exactly: {line}"
            pins[name.lower()] = pinned
            assert version(name) == pinned, f"{name}: installed {version(name)}, pinned {pinned}"
    extras = _setup_keyword("extras_require")
    assert "peers" in extras, "setup.py declares no peers extra"
    for requirement in extras["peers"]:
        name, _, pinned = requirement.partition("==")
        assert pins[name.lower()] == pinned, requirement
    assert {"hmmlearn"} <= set(pins)


# ------------------------------------------------------------------ HMM detector
@pytest.fixture(scope="module")
def detector() -> HMMDetector:
    rng = np.random.default_rng(3)
    successes = {
        f"phase{p}": [_nominal(rng, p, int(rng.integers(40, 60))) for _ in range(15)]
        for p in (0, 1)
    }
    return HMMDetector().fit(successes)


def test_the_cumulative_loglik_is_hmmlearns_score_of_every_prefix(detector: HMMDetector) -> None:
    rng = np.random.default_rng(4)
    seq = _nominal(rng, 0, 30)
    curve = detector.loglik("phase0", seq)
    model, scaled = detector.models_["phase0"], detector.scalers_["phase0"].transform(seq)
    assert curve.shape == (30,)
    for t in (1, 2, 10, 30):
        assert curve[t - 1] == pytest.approx(model.score(scaled[:t]), rel=1e-9, abs=1e-9)


def test_the_hmm_detector_scores_an_altered_sequence_above_held_out_nominal_ones(
    detector: HMMDetector,
) -> None:
    rng = np.random.default_rng(5)
    nominal = [detector.score("phase0", _nominal(rng, 0, 50)).max() for _ in range(10)]
    threshold = max(nominal)
    for _ in range(10):
        seq = _nominal(rng, 0, 50)
        seq[25:, 2] += 4.0  # a 4 N step in Fz half-way through
        score = detector.score("phase0", seq)
        assert score.max() > threshold
        assert score[:25].max() <= threshold + 1.0, "the alteration raised the score before it"
    # another sub-task's wrench is not nominal for this one
    assert detector.score("phase0", _nominal(rng, 1, 50)).max() > threshold


def test_the_hmm_detector_scores_unknown_phases_infinite_and_long_runs_finitely(
    detector: HMMDetector,
) -> None:
    rng = np.random.default_rng(6)
    assert np.isposinf(detector.score("no such phase", _nominal(rng, 0, 5))).all()
    long = detector.score("phase1", _nominal(rng, 1, 200))
    assert long.shape == (200,) and np.isfinite(long).all()
    assert detector.phases_ == ("phase0", "phase1")
    assert clone(detector).get_params() == {
        "covariance_type": "diag",
        "n_components": 5,
        "n_iter": 100,
        "random_state": 0,
    }


def test_the_hmms_handle_sequences_shorter_than_their_states() -> None:
    rng = np.random.default_rng(7)
    tiny = HMMDetector(n_components=5).fit({"a": [_nominal(rng, 0, 2)], "b": [np.empty((0, 6))]})
    assert tiny.models_["a"].n_components == 2
    assert "b" not in tiny.phases_
    assert np.isfinite(tiny.score("a", _nominal(rng, 0, 4))).all()
    assert tiny.score("a", np.empty((0, 6))).shape == (0,)
    windows = [_failure(rng, k % 2, 1 + k % 3) for k in range(6)] + [np.empty((0, 6))]
    labels = ["a", "b"] * 3 + ["c"]
    classifier = HMMClassifier(n_components=5).fit(windows, labels)
    proba = classifier.predict_proba([_failure(rng, 0, 1), np.empty((0, 6))])
    assert proba[:, 2].tolist() == [0.0, 0.0], "a class without a model has no probability"
    assert proba[1, :2] == pytest.approx([0.5, 0.5])


# ------------------------------------------------------------------ classifiers
def test_the_hmm_classifier_names_the_classes_and_not_shuffled_labels() -> None:
    windows, labels = _failures(seed=8, per_class=15)
    assert _cv_accuracy(HMMClassifier(), windows, labels) >= 0.9
    shuffled = np.random.default_rng(0).permutation(labels)
    assert _cv_accuracy(HMMClassifier(), windows, shuffled) < 0.6


def test_the_hmm_classifier_reads_n_and_n_m_alike() -> None:
    """Standardised inside: a torque channel in N mm instead of N m changes nothing."""
    windows, labels = _failures(seed=9, per_class=8)
    test, _ = _failures(seed=10, per_class=4)
    units = np.array([1.0, 1.0, 1.0, 1000.0, 1000.0, 1000.0])
    plain = HMMClassifier().fit(windows, labels)
    scaled = HMMClassifier().fit([w * units for w in windows], labels)
    assert plain.predict(test).tolist() == scaled.predict([w * units for w in test]).tolist()
    proba = plain.predict_proba(test)
    assert proba.sum(axis=1) == pytest.approx(np.ones(len(test)))
    assert (plain.classes_[proba.argmax(axis=1)] == plain.predict(test)).all()


def test_minirocket_names_the_classes_and_not_shuffled_labels() -> None:
    windows, labels = _failures(seed=11, per_class=15)
    assert _cv_accuracy(MiniRocketClassifier(), windows, labels) >= 0.9
    shuffled = np.random.default_rng(0).permutation(labels)
    assert _cv_accuracy(MiniRocketClassifier(), windows, shuffled) < 0.6
    model = MiniRocketClassifier().fit(windows, labels)
    assert model.decision_function(windows[:4]).shape == (4, 3)
    assert model.transform_.n_kernels_ == 10_000


def test_minirocket_resamples_each_window_linearly_along_time() -> None:
    ramp = np.stack([np.arange(11.0), -2.0 * np.arange(11.0)], axis=1)
    out = resample(ramp, 21)
    assert out.shape == (2, 21)
    assert out[0] == pytest.approx(np.arange(21) / 2)
    assert out[1] == pytest.approx(-np.arange(21.0))
    assert resample(np.array([[3.0, 4.0]]), 9).tolist() == [[3.0] * 9, [4.0] * 9]
    with pytest.raises(ValueError, match="n_points"):
        MiniRocketClassifier(n_points=8).fit([ramp, ramp], ["a", "b"])
