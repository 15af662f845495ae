"""launch/introspection.launch.py and the ament packaging, tested without launch / launch_ros.

launch and launch_ros have no PyPI wheels, so stand-in modules with the real constructors'
signatures record what the launch file builds. The package is "installed" into a temporary prefix
from setup.py's own data_files, so every check also covers what colcon / pip would install.
"""

from __future__ import annotations

import ast
import dataclasses
import importlib.util
import runpy
import shutil
import sys
import types
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import pytest
import setuptools
import yaml

from rcbht_introspection.configure.params import NODE_NAMES, config_from_parameters
from rcbht_introspection.errors import InputError

REPO = Path(__file__).resolve().parents[1]
LAUNCH_FILE = REPO / "launch" / "introspection.launch.py"
PACKAGE = "rcbht_introspection"
CONFIG_CLASSES = {node: cls for cls, node in NODE_NAMES.items()}


class LaunchDescription:
    """Stand-in for launch.LaunchDescription."""

    def __init__(
        self, initial_entities: Any = None, *, deprecated_reason: str | None = None
    ) -> None:
        self.entities = list(initial_entities or [])


class LaunchContext:
    """Stand-in for launch.LaunchContext: only the launch configurations."""

    def __init__(self, launch_configurations: dict[str, str]) -> None:
        self.launch_configurations = dict(launch_configurations)


class DeclareLaunchArgument:
    """Stand-in for launch.actions.DeclareLaunchArgument."""

    def __init__(
        self,
        name: str,
        *,
        default_value: Any = None,
        description: str | None = None,
        choices: list[str] | None = None,
        **kwargs: Any,
    ) -> None:
        self.name, self.default_value, self.choices = name, default_value, choices


class OpaqueFunction:
    """Stand-in for launch.actions.OpaqueFunction."""

    def __init__(
        self, *, function: Any, args: Any = None, kwargs: Any = None, **left_over: Any
    ) -> None:
        assert callable(function)
        self.function, self.args, self.kwargs = function, args or [], kwargs or {}

    def execute(self, context: LaunchContext) -> list[Any]:
        """What launch does with it: call the function with the context."""
        return list(self.function(context, *self.args, **self.kwargs) or [])


class LaunchConfiguration:
    """Stand-in for launch.substitutions.LaunchConfiguration (perform as the real one)."""

    def __init__(self, variable_name: str, *, default: Any = None) -> None:
        self.variable_name, self.default = variable_name, default

    def perform(self, context: LaunchContext) -> str:
        """The configuration's value, else the default, else an error."""
        if self.variable_name in context.launch_configurations:
            return context.launch_configurations[self.variable_name]
        if self.default is None:
            raise KeyError(f"launch configuration '{self.variable_name}' does not exist")
        return str(self.default)


class Node:
    """Stand-in for launch_ros.actions.Node: records the constructor arguments."""

    def __init__(
        self,
        *,
        executable: str,
        package: str | None = None,
        name: str | None = None,
        namespace: str | None = None,
        exec_name: str | None = None,
        parameters: list[Any] | None = None,
        remappings: list[Any] | None = None,
        ros_arguments: list[Any] | None = None,
        arguments: list[Any] | None = None,
        **kwargs: Any,
    ) -> None:
        self.executable, self.package, self.name = executable, package, name
        self.parameters = list(parameters or [])


@dataclass
class Install:
    """A package installed from setup.py's data_files into a temporary prefix."""

    prefix: Path
    executables: set[str]

    @property
    def share(self) -> Path:
        """<prefix>/share/rcbht_introspection."""
        return self.prefix / "share" / PACKAGE


def setup_arguments(monkeypatch: pytest.MonkeyPatch) -> dict[str, Any]:
    """The keyword arguments setup.py passes to setuptools.setup (run in the repository)."""
    recorded: dict[str, Any] = {}
    monkeypatch.setattr(setuptools, "setup", lambda **kwargs: recorded.update(kwargs))
    monkeypatch.chdir(REPO)
    runpy.run_path(str(REPO / "setup.py"), run_name="__main__")
    return recorded


@pytest.fixture
def install(monkeypatch: pytest.MonkeyPatch, tmp_path: Path) -> Install:
    """setup.py's data_files copied into tmp_path; executables as `ros2 run` finds them."""
    args = setup_arguments(monkeypatch)
    for dest, files in args["data_files"]:
        (tmp_path / dest).mkdir(parents=True, exist_ok=True)
        for f in files:
            shutil.copy(REPO / f, tmp_path / dest / Path(f).name)
    lib = tmp_path / "lib" / PACKAGE
    executables = {p.name for p in lib.iterdir()} if lib.is_dir() else set()
    # console_scripts: setup.cfg's install_scripts puts them into lib/<package> under colcon
    scripts = args.get("entry_points", {}).get("console_scripts", [])
    executables |= {spec.split("=")[0].strip() for spec in scripts}
    return Install(tmp_path, executables)


@pytest.fixture
def launch_api(monkeypatch: pytest.MonkeyPatch, install: Install) -> None:
    """Stand-in launch, launch_ros and ament_index_python modules in sys.modules."""

    def get_package_share_directory(package_name: str) -> str:
        if package_name != PACKAGE:
            raise LookupError(f"package '{package_name}' not found")
        return str(install.share)

    contents = {
        "launch": {"LaunchDescription": LaunchDescription, "LaunchContext": LaunchContext},
        "launch.actions": {
            "DeclareLaunchArgument": DeclareLaunchArgument,
            "OpaqueFunction": OpaqueFunction,
        },
        "launch.substitutions": {"LaunchConfiguration": LaunchConfiguration},
        "launch_ros": {},
        "launch_ros.actions": {"Node": Node},
        "ament_index_python": {},
        "ament_index_python.packages": {"get_package_share_directory": get_package_share_directory},
    }
    for name, attributes in contents.items():
        module = types.ModuleType(name)
        module.__dict__.update(attributes)
        monkeypatch.setitem(sys.modules, name, module)
    for name in contents:
        parent, _, child = name.rpartition(".")
        if parent:
            monkeypatch.setattr(sys.modules[parent], child, sys.modules[name], raising=False)


def load_launch_file(path: Path) -> types.ModuleType:
    """Import a launch file as `ros2 launch` does (a module from a file path)."""
    spec = importlib.util.spec_from_file_location("introspection_launch", path)
    assert spec is not None and spec.loader is not None
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


def launch(path: Path, **arguments: str) -> list[Node]:
    """generate_launch_description(), then the actions launch would run with `arguments`."""
    description = load_launch_file(path).generate_launch_description()
    declared = {e.name: e for e in description.entities if isinstance(e, DeclareLaunchArgument)}
    unknown = set(arguments) - set(declared)
    assert not unknown, f"not declared launch arguments: {sorted(unknown)}"
    context = LaunchContext({n: a.default_value for n, a in declared.items()} | arguments)
    actions: list[Any] = []
    for entity in description.entities:
        if isinstance(entity, OpaqueFunction):
            actions += entity.execute(context)
        elif not isinstance(entity, DeclareLaunchArgument):
            actions.append(entity)
    return [a for a in actions if isinstance(a, Node)]


def effective_parameters(node: Node, install: Install) -> dict[str, Any]:
    """Check one Node action against the install; the node's parameters, validated."""
    assert node.package == PACKAGE, f"{node.executable}: package {node.package!r}"
    assert node.executable in install.executables, (
        f"executable {node.executable!r} is not installed (installed: {sorted(install.executables)})"
    )
    node_name = node.name or node.executable
    assert node_name in CONFIG_CLASSES, f"no parameters known for node {node_name!r}"
    cls = CONFIG_CLASSES[node_name]
    fields = {f.name for f in dataclasses.fields(cls)}
    values: dict[str, Any] = {}
    for entry in node.parameters:
        if isinstance(entry, dict):
            unknown = set(entry) - fields
            assert not unknown, f"{node_name}: unknown parameters {sorted(unknown)}"
            values.update(entry)
            continue
        path = Path(entry)
        assert path.is_file(), f"{node_name}: parameter file {path} is not installed"
        relative = path.relative_to(install.share)
        assert (REPO / relative).is_file(), f"{node_name}: {relative} is not in the repository"
        data = yaml.safe_load(path.read_text())
        section = data.get(node_name, data.get("/**"))
        assert section and "ros__parameters" in section, f"{relative}: no {node_name} section"
        values.update(section["ros__parameters"])
    known = {k: v for k, v in values.items() if k in fields}  # e.g. `autostart` is the node's own
    try:
        config_from_parameters(cls, known)
    except InputError as exc:
        raise AssertionError(f"{node_name}: {exc}") from None
    return values


def node_parameters(nodes: list[Node], install: Install) -> dict[str, dict[str, Any]]:
    """Executable -> effective parameters, every node checked."""
    return {node.executable: effective_parameters(node, install) for node in nodes}


def test_launch_file_parses() -> None:
    tree = ast.parse(LAUNCH_FILE.read_text(), filename=str(LAUNCH_FILE))
    compile(tree, str(LAUNCH_FILE), "exec")
    functions = {n.name for n in tree.body if isinstance(n, ast.FunctionDef)}
    assert "generate_launch_description" in functions


@pytest.mark.parametrize(
    ("arguments", "arms", "wrench_topics"),
    [
        ({}, ["R"], ["/wrench"]),
        ({"arms": "one"}, ["R"], ["/wrench"]),
        ({"arms": "two"}, ["L", "R"], ["/L/wrench", "/R/wrench"]),
        ({"arms": "[L, R]"}, ["L", "R"], ["/L/wrench", "/R/wrench"]),
        ({"arms": "[L]"}, ["L"], ["/wrench"]),
        ({"arms": " ['L','R'] "}, ["L", "R"], ["/L/wrench", "/R/wrench"]),
    ],
)
def test_launch_starts_both_nodes_with_their_parameters(
    launch_api: None,
    install: Install,
    arguments: dict[str, str],
    arms: list[str],
    wrench_topics: list[str],
) -> None:
    params = node_parameters(launch(LAUNCH_FILE, **arguments), install)
    assert sorted(params) == ["classifier_node", "segmenter_node"]
    assert list(params["segmenter_node"]["arms"]) == arms
    assert list(params["segmenter_node"]["wrench_topics"]) == wrench_topics
    assert list(params["classifier_node"]["arms"]) == arms
    assert params["classifier_node"]["model_file"] == ""


def test_launch_arguments_reach_the_nodes(
    launch_api: None, install: Install, tmp_path: Path
) -> None:
    params_file = tmp_path / "classifier.yaml"
    params_file.write_text(
        yaml.safe_dump({"classifier_node": {"ros__parameters": {"mode": "window"}}})
    )
    nodes = launch(LAUNCH_FILE, model_file="/data/model.rcbht", classifier_params=str(params_file))
    classifier = next(n for n in nodes if n.executable == "classifier_node")
    assert classifier.parameters[0] == str(params_file)
    assert classifier.parameters[-1]["model_file"] == "/data/model.rcbht"
    segmenter = next(n for n in nodes if n.executable == "segmenter_node")
    assert len(segmenter.parameters) == 1  # no file there yet (a teaching cold start)
    model = tmp_path / "model.rcbht"
    model.write_bytes(b"")
    nodes = launch(LAUNCH_FILE, model_file=str(model))
    segmenter = next(n for n in nodes if n.executable == "segmenter_node")
    assert segmenter.parameters[-1] == {"taxonomy_model_file": str(model)}  # the model's profile
    assert node_parameters(nodes, install)["segmenter_node"]["taxonomy_model_file"] == str(model)


@pytest.mark.parametrize(
    ("arguments", "arms", "verifier_file"),
    [
        ({"verifier": "true"}, ["R"], ""),
        ({"verifier": "true", "arms": "two"}, ["L", "R"], ""),
        ({"verifier_file": "/data/v.npz", "arms": "two"}, ["L", "R"], "/data/v.npz"),
    ],
)
def test_the_verifier_argument_adds_verifier_node(
    launch_api: None,
    install: Install,
    arguments: dict[str, str],
    arms: list[str],
    verifier_file: str,
) -> None:
    params = node_parameters(launch(LAUNCH_FILE, **arguments), install)
    assert sorted(params) == ["classifier_node", "segmenter_node", "verifier_node"]
    verifier = params["verifier_node"]
    assert list(verifier["arms"]) == arms
    assert list(verifier["wrench_topics"]) == list(params["segmenter_node"]["wrench_topics"])
    assert verifier["verifier_file"] == verifier_file


def test_closed_loop_adds_the_simulated_cell_and_the_planner(
    launch_api: None, install: Install
) -> None:
    nodes = launch(LAUNCH_FILE, closed_loop="true", policy="oracle", verifier_file="/data/v.npz")
    params = node_parameters(nodes, install)
    assert sorted(params) == [
        "classifier_node", "planner_node", "segmenter_node", "sim_node", "verifier_node"
    ]  # fmt: skip
    assert params["planner_node"]["policy"] == "oracle"
    assert params["planner_node"]["verifier_file"] == params["verifier_node"]["verifier_file"]
    assert params["sim_node"]["wrench_topic"] == params["segmenter_node"]["wrench_topics"][0]
    with pytest.raises(ValueError, match="closed_loop"):
        launch(LAUNCH_FILE, closed_loop="yes")


def test_verifier_false_leaves_it_out_and_a_bad_value_fails(launch_api: None) -> None:
    nodes = launch(LAUNCH_FILE, verifier="false", verifier_file="/data/v.npz")
    assert "verifier_node" not in {n.executable for n in nodes}
    with pytest.raises(ValueError, match="verifier"):
        launch(LAUNCH_FILE, verifier="maybe")


@pytest.mark.parametrize("arms", ["[A, B, C]", "[L, L]", "[]", "three", "L, R"])
def test_bad_arms_argument_fails_at_launch(launch_api: None, arms: str) -> None:
    with pytest.raises(ValueError, match="arms"):
        launch(LAUNCH_FILE, arms=arms)


@pytest.mark.parametrize(
    ("old", "new", "error"),
    [
        ("executable=name", 'executable=name.replace("ter", "tor")', "executable 'segmentor_node'"),
        ('"classifier.yaml"', '"classifer.yaml"', "parameter file .*classifer.yaml"),
        ('"wrench_topics": topics', '"wrench_topics": topics[:1]', "wrench_topics"),
        ('{"arms": arms, "wrench', '{"arm": arms, "wrench', r"unknown parameters \['arm'\]"),
    ],
)
def test_the_checks_catch_a_broken_launch_file(
    launch_api: None, install: Install, tmp_path: Path, old: str, new: str, error: str
) -> None:
    source = LAUNCH_FILE.read_text()
    assert old in source
    broken = tmp_path / "broken.launch.py"
    broken.write_text(source.replace(old, new, 1))
    with pytest.raises(AssertionError, match=error):
        node_parameters(launch(broken, arms="two"), install)


def test_node_executables_import_an_existing_main(install: Install) -> None:
    for exe in ("segmenter_node", "classifier_node", "verifier_node"):
        script = ast.parse((install.prefix / "lib" / PACKAGE / exe).read_text())
        modules = [
            n.module
            for n in ast.walk(script)
            if isinstance(n, ast.ImportFrom) and any(a.name == "main" for a in n.names)
        ]
        assert len(modules) == 1 and modules[0], f"{exe}: no `from <module> import main`"
        spec = importlib.util.find_spec(modules[0])
        assert spec is not None and spec.origin is not None, f"{exe}: no module {modules[0]}"
        tree = ast.parse(Path(spec.origin).read_text())
        assert any(isinstance(n, ast.FunctionDef) and n.name == "main" for n in tree.body), exe


def test_setup_installs_the_ament_files(install: Install) -> None:
    index = install.prefix / "share" / "ament_index" / "resource_index" / "packages" / PACKAGE
    assert index.is_file()
    assert (install.share / "package.xml").is_file()
    for pattern in ("config/*.yaml", "config/*.xml", "launch/*.launch.py"):
        sources = sorted(REPO.glob(pattern))
        assert sources, pattern
        for source in sources:
            assert (install.share / source.relative_to(REPO)).is_file(), source


# import name -> rosdep key, where they differ (ROS packages are imported by their own name)
ROSDEP_KEYS = {
    "numpy": "python3-numpy",
    "scipy": "python3-scipy",
    "sklearn": "python3-sklearn",
    "joblib": "python3-joblib",
    "yaml": "python3-yaml",
    "matplotlib": "python3-matplotlib",
    "tqdm": "python3-tqdm",
    "rosbags": "python3-rosbags-pip",
    "mujoco": "python3-mujoco-pip",
    "skops": "python3-skops-pip",
    "aeon": "python3-aeon-pip",
}
ROSDISTRO_PIP_KEYS = {"python3-rosbags-pip"}  # defined by rosdistro
OPTIONAL_EXTRAS = {"peers", "sim", "plots"}
"""Packages of an optional pip extra (setup.py extras_require): verify-eval's anchor methods,
the MuJoCo simulator and the plots; a robot that runs the nodes needs none of them."""
OPTIONAL_IMPORTS = {"dask", "tqdm"}
"""Modules of an optional pip extra imported where a command option asks for them (fleet:
--scheduler, rcbht_introspection/fleet.py) or with a fallback (progress: plain lines without tqdm)."""


def test_package_xml_lists_every_run_dependency() -> None:
    from catkin_pkg.package import parse_package

    package = parse_package(str(REPO / "package.xml"))
    package.validate()
    exec_depends = {d.name for d in package.exec_depends}
    imported = set()
    for source in (REPO / PACKAGE).rglob("*.py"):
        if source.parent.name in OPTIONAL_EXTRAS:
            continue  # installed by its pip extra (setup.py), not needed to run the nodes
        tree = ast.parse(source.read_text())
        typing_only = {  # `if TYPE_CHECKING:` imports are read by the type checker, never run
            id(n)
            for block in ast.walk(tree)
            if isinstance(block, ast.If) and ast.unparse(block.test).endswith("TYPE_CHECKING")
            for n in ast.walk(block)
        }
        for node in ast.walk(tree):
            if id(node) in typing_only:
                continue
            if isinstance(node, ast.Import):
                imported |= {a.name.split(".")[0] for a in node.names}
            elif isinstance(node, ast.ImportFrom) and node.level == 0 and node.module:
                imported.add(node.module.split(".")[0])
    third_party = imported - set(sys.stdlib_module_names) - {PACKAGE} - OPTIONAL_IMPORTS
    needed = {ROSDEP_KEYS.get(name, name) for name in third_party}
    needed |= {"launch", "launch_ros", "lifecycle_msgs", "diagnostic_msgs"}
    assert not needed - exec_depends, (
        f"package.xml misses exec_depend {sorted(needed - exec_depends)}"
    )
    libraries = {d for d in exec_depends if d.startswith("python3-")}
    assert libraries <= needed, (
        f"package.xml lists beyond the runtime: {sorted(libraries - needed)}"
    )
    local_keys = yaml.safe_load((REPO / "rosdep.yaml").read_text())
    for key in exec_depends:
        if key.endswith("-pip"):
            assert key in ROSDISTRO_PIP_KEYS or key in local_keys, f"no rosdep definition: {key}"
