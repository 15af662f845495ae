"""A robot that runs the nodes needs the runtime only: with the extras' libraries made
unimportable (simulator, plots, progress bars, peers, fleet), every node module imports, every
`rcbht` subcommand prints its help, and `rcbht train` / `verify-train` fit on recorded trials.
aeon (MiniRocket) is not an extra: the verifier's shape head reads the evidence with it."""

from __future__ import annotations

import ast
import subprocess
import sys
from pathlib import Path

import pytest
from conftest import SIM_SUCCESS
from ros_support import require_ros

REPO = Path(__file__).resolve().parents[1]
EXTRAS = ("mujoco", "matplotlib", "tqdm", "hmmlearn", "dask", "distributed")
"""Top-level modules of the optional extras (sim, plots, peers, fleet)."""
HIDE = f"import sys\nfor name in {EXTRAS!r}:\n    sys.modules[name] = None\n"
"""A module set to None in sys.modules raises ImportError on import, as if not installed."""


def _without_extras(code: str) -> subprocess.CompletedProcess[str]:
    """Run `code` in a fresh interpreter where no extra can be imported."""
    return subprocess.run(
        [sys.executable, "-c", HIDE + code], capture_output=True, text=True, cwd=REPO, timeout=300
    )


def test_hidden_extras_cannot_be_imported() -> None:
    """The check below can fail: the simulator does not import with its extra hidden."""
    out = _without_extras("import rcbht_introspection.sim.simulate")
    assert out.returncode != 0 and "mujoco" in out.stderr, out.stderr


@pytest.mark.ros
def test_every_node_module_imports_without_the_extras() -> None:
    require_ros()
    code = (
        "import importlib, pkgutil, rcbht_introspection.nodes as n\n"
        "names = [m.name for m in pkgutil.walk_packages(n.__path__, n.__name__ + '.')]\n"
        "for name in names:\n    importlib.import_module(name)\n"
        "print(len(names))\n"
    )
    out = _without_extras(code)
    assert out.returncode == 0, out.stderr
    assert int(out.stdout) >= 3


def test_every_subcommand_helps_without_the_extras() -> None:
    code = (
        "import contextlib, io\n"
        "from rcbht_introspection.cli import build_parser, main\n"
        "sub = build_parser()._subparsers._group_actions[0].choices\n"
        "for command in ['', *sub]:\n"
        "    with contextlib.redirect_stdout(io.StringIO()), contextlib.suppress(SystemExit):\n"
        "        main([command, '--help'] if command else ['--help'])\n"
        "print(len(sub))\n"
    )
    out = _without_extras(code)
    assert out.returncode == 0, out.stderr
    assert int(out.stdout) >= 10


def test_train_and_verify_train_run_without_the_extras(sim_data: Path, tmp_path: Path) -> None:
    trials = str(sim_data / SIM_SUCCESS)
    model, verifier = tmp_path / "m.skops", tmp_path / "v.skops"
    code = (
        "from rcbht_introspection.cli import main\n"
        f"assert main(['train', {trials!r}, '--out', {str(model)!r}]) == 0\n"
        f"assert main(['verify-train', {trials!r}, '--out', {str(verifier)!r}]) == 0\n"
    )
    out = _without_extras(code)
    assert out.returncode == 0, out.stderr
    assert model.stat().st_size > 0 and verifier.stat().st_size > 0


def _setup_keyword(name: str) -> object:
    """The literal value of one keyword of the setup() call in setup.py."""
    for node in ast.walk(ast.parse((REPO / "setup.py").read_text())):
        if isinstance(node, ast.keyword) and node.arg == name:
            return ast.literal_eval(node.value)
    raise AssertionError(f"setup.py has no {name}")


def _requirement_pins() -> dict[str, str]:
    """name (lower case) -> version of every `name==version` line of requirements*.txt."""
    pins = {}
    for path in REPO.glob("requirements*.txt"):
        for line in path.read_text().splitlines():
            name, sep, version = line.split("#")[0].strip().partition("==")
            if sep:
                pins[name.lower().replace("_", "-")] = version
    return pins


def test_setup_pins_the_runtime_and_the_extras_as_the_requirements_do() -> None:
    pins = _requirement_pins()
    extras = _setup_keyword("extras_require")
    assert isinstance(extras, dict) and {"sim", "plots", "peers", "fleet"} <= set(extras)
    runtime = _setup_keyword("install_requires")
    assert isinstance(runtime, list)
    for requirement in [*runtime, *(r for group in extras.values() for r in group)]:
        name, sep, version = requirement.partition("==")
        assert sep, f"setup.py: {requirement} is not pinned exactly"
        assert pins.get(name.lower()) == version, (requirement, pins.get(name.lower()))
    names = {r.partition("==")[0].lower() for r in runtime}
    assert names.isdisjoint({"mujoco", "matplotlib", "tqdm", "hmmlearn", "dask"}), names
    assert "aeon" in names  # the verifier's shape head reads the evidence with MiniRocket
