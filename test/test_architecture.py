"""The package's import graph: data flows one way, and the core never imports ROS or plotting.

Every import statement counts, at module top or inside a function: a function-level import is
still a dependency, it only hides it.
"""

from __future__ import annotations

import ast
from pathlib import Path

import pytest

PACKAGE = Path(__file__).resolve().parents[1] / "rcbht_introspection"
CORE = (
    "taxonomy", "summaries", "grammar", "learn", "live", "sim", "io", "audit", "plan", "verify",
    "peers", "configure",
)  # fmt: skip
"""Subpackages of the pure core (NumPy, SciPy, scikit-learn, MuJoCo; io/ also reads bags with the
pure-Python rosbags; peers/ the anchors' hmmlearn and aeon)."""
ROS_AND_PLOTTING = frozenset(
    {"rclpy", "matplotlib", "geometry_msgs", "std_msgs", "rcbht_interfaces", "diagnostic_msgs"}
)
ROS_FREE = (
    "waiting",
    "lifetime",
    "config_files",
    "replay.scoring",
    "replay.supervision",
    "closed_loop.experiment",
)
"""Modules outside the core that must work without ROS, with all they import: the one polling
loop (every layer waits with it), the replay's scores (unit-tested without ROS) and the process
supervision (the node processes import rclpy, their supervisor does not), and the offline
closed loop."""


def _modules() -> dict[str, Path]:
    out = {}
    for path in PACKAGE.rglob("*.py"):
        parts = path.relative_to(PACKAGE.parent).with_suffix("").parts
        out[".".join(parts[:-1] if parts[-1] == "__init__" else parts)] = path
    return out


def _imports(path: Path) -> set[str]:
    """Every module name imported by the file (absolute names); a file that calls
    `import_module` also imports each of the package's modules a string of it names."""
    names = set()
    tree = ast.parse(path.read_text())
    loads = False
    for node in ast.walk(tree):
        if isinstance(node, ast.ImportFrom) and node.module and node.level == 0:
            names.add(node.module)
            names.update(f"{node.module}.{alias.name}" for alias in node.names)
        elif isinstance(node, ast.Import):
            names.update(alias.name for alias in node.names)
        elif isinstance(node, ast.Attribute | ast.Name):
            loads |= (node.attr if isinstance(node, ast.Attribute) else node.id) == "import_module"
    if loads:
        names.update(
            node.value
            for node in ast.walk(tree)
            if isinstance(node, ast.Constant)
            and isinstance(node.value, str)
            and node.value.startswith(f"{PACKAGE.name}.")
        )
    return names


def _graph() -> dict[str, set[str]]:
    """Module -> package modules it imports."""
    modules = _modules()
    return {
        name: {
            m for m in _imports(path) if m in modules and m != name and not name.startswith(m + ".")
        }
        for name, path in modules.items()
    }


def _cycles(graph: dict[str, set[str]]) -> list[list[str]]:
    """Strongly connected components with more than one node (Tarjan)."""
    index: dict[str, int] = {}
    low: dict[str, int] = {}
    stack: list[str] = []
    on_stack: set[str] = set()
    found: list[list[str]] = []

    def visit(v: str) -> None:
        index[v] = low[v] = len(index)
        stack.append(v)
        on_stack.add(v)
        for w in graph.get(v, ()):
            if w not in index:
                visit(w)
                low[v] = min(low[v], low[w])
            elif w in on_stack:
                low[v] = min(low[v], index[w])
        if low[v] == index[v]:
            component = []
            while True:
                w = stack.pop()
                on_stack.discard(w)
                component.append(w)
                if w == v:
                    break
            if len(component) > 1:
                found.append(sorted(component))

    for v in sorted(graph):
        if v not in index:
            visit(v)
    return found


def _subpackage(module: str) -> str:
    return module.split(".")[1]


def test_no_module_imports_itself_back() -> None:
    assert _cycles(_graph()) == []


def test_no_two_subpackages_import_each_other() -> None:
    packages: dict[str, set[str]] = {}
    for name, targets in _graph().items():
        if len(name.split(".")) < 3:
            continue  # top-level modules (cli, config, errors) are not subpackages
        packages.setdefault(_subpackage(name), set()).update(
            _subpackage(t) for t in targets if len(t.split(".")) >= 3
        )
    graph = {k: v - {k} for k, v in packages.items()}
    assert _cycles(graph) == []


@pytest.mark.parametrize("subpackage", CORE)
def test_the_core_imports_no_ros_and_no_plotting(subpackage: str) -> None:
    for name, path in _modules().items():
        if name.startswith(f"rcbht_introspection.{subpackage}"):
            roots = {m.split(".")[0] for m in _imports(path)}
            forbidden = roots & ROS_AND_PLOTTING
            assert not forbidden, f"{path.name} imports {sorted(forbidden)}"


@pytest.mark.parametrize("module", ROS_FREE)
def test_ros_free_modules_reach_no_ros_and_no_plotting(module: str) -> None:
    graph, modules = _graph(), _modules()
    start = f"rcbht_introspection.{module}"
    assert start in modules
    reached, todo = {start}, [start]
    while todo:
        for target in graph[todo.pop()] - reached:
            reached.add(target)
            todo.append(target)
    for name in sorted(reached):
        forbidden = {m.split(".")[0] for m in _imports(modules[name])} & ROS_AND_PLOTTING
        assert not forbidden, f"{start} imports {name}, which imports {sorted(forbidden)}"


PRIVATE_ROS = ("rclpy.impl", "_rclpy", "rclpy._rclpy_pybind11")
"""rclpy's private implementation: the nodes use its public API only."""
CDR_DECODERS = ("decode_wrench", "decode_wrench_sample", "deserialize_message")
"""Decoding messages by hand: the nodes take rclpy's message objects."""


def test_the_nodes_use_rclpy_s_public_api_and_decode_no_cdr() -> None:
    for name, path in _modules().items():
        if name.startswith("rcbht_introspection.nodes."):
            imported = _imports(path)
            private = {m for m in imported if m.startswith(PRIVATE_ROS)}
            decoders = {m for m in imported if m.rsplit(".", 1)[-1] in CDR_DECODERS}
            assert not private | decoders, f"{path.name} imports {sorted(private | decoders)}"


def test_modules_loaded_by_name_are_edges_of_the_graph() -> None:
    """`rcbht` loads its subcommands and `make bench` its benchmarks by name: the graph has
    those edges, so the rules above hold for what they load."""
    graph = _graph()
    assert "rcbht_introspection.commands.closed_loop" in graph["rcbht_introspection.cli"]
    assert "rcbht_introspection.bench.ros" in graph["rcbht_introspection.bench.__main__"]


def test_the_cycle_finder_finds_a_cycle() -> None:
    assert _cycles({"a": {"b"}, "b": {"c"}, "c": {"a"}, "d": {"a"}}) == [["a", "b", "c"]]


def test_the_cli_help_imports_no_engine() -> None:
    """`rcbht --help` and argument errors answer without NumPy (subcommands import lazily)."""
    import subprocess
    import sys

    code = (
        "import contextlib, io, sys\n"
        "from rcbht_introspection.cli import main\n"
        "with contextlib.suppress(SystemExit), contextlib.redirect_stdout(io.StringIO()):\n"
        "    main(['--help'])\n"
        "print(sorted(m for m in ('numpy', 'scipy', 'yaml', 'rosbags') if m in sys.modules))\n"
    )
    out = subprocess.run(
        [sys.executable, "-c", code], capture_output=True, text=True, check=True, cwd=PACKAGE.parent
    )
    assert out.stdout.strip() == "[]", out.stdout


def test_segmenter_node_starts_without_scikit_learn() -> None:
    """segmenter_node runs no model: it starts in a third of the classifier's time (every ROS test
    starts one). scikit-learn comes with a model file (classifier, verifier)."""
    import subprocess
    import sys

    from ros_support import require_ros

    require_ros()
    code = (
        "import sys\n"
        "import rcbht_introspection.nodes.segmenter_node\n"
        "print(sorted(m for m in ('sklearn', 'scipy.stats', 'pandas') if m in sys.modules))\n"
    )
    out = subprocess.run(
        [sys.executable, "-c", code], capture_output=True, text=True, check=True, cwd=PACKAGE.parent
    )
    assert out.stdout.strip() == "[]", out.stdout


MAX_FUNCTION_LINES = 60


def _long_functions(source: str) -> list[tuple[str, int]]:
    """(name, lines) of every function in `source` longer than MAX_FUNCTION_LINES."""
    return [
        (node.name, node.end_lineno - node.lineno + 1)
        for node in ast.walk(ast.parse(source))
        if isinstance(node, ast.FunctionDef | ast.AsyncFunctionDef)
        and node.end_lineno is not None
        and node.end_lineno - node.lineno + 1 > MAX_FUNCTION_LINES
    ]


def test_no_function_of_the_package_is_over_60_lines() -> None:
    long = {
        str(path.relative_to(PACKAGE)): found
        for path in sorted(PACKAGE.rglob("*.py"))
        if (found := _long_functions(path.read_text()))
    }
    assert not long, long


def test_the_length_check_sees_a_long_function() -> None:
    def function(name: str, lines: int) -> str:
        return f"def {name}():\n" + "".join(f"    x{i} = {i}\n" for i in range(lines - 1))

    assert _long_functions(function("f", MAX_FUNCTION_LINES + 1)) == [("f", 61)]
    assert _long_functions(function("g", MAX_FUNCTION_LINES)) == []


NODE_LINES, SHARED_NODE_LINES = 150, 500
"""Lines of code (non-blank, non-comment, docstrings included) of a node module, and of the
nodes' shared modules together: the logic lives in the core, a node adapts messages."""


def _code_lines(path: Path) -> int:
    return sum(1 for line in path.read_text().splitlines() if line.strip()[:1] not in ("", "#"))


def test_nodes_are_thin() -> None:
    sizes = {p.name: _code_lines(p) for p in sorted((PACKAGE / "nodes").glob("*.py"))}
    nodes = {name: n for name, n in sizes.items() if name.endswith("_node.py")}
    shared = sum(n for name, n in sizes.items() if name not in nodes)
    assert len(nodes) == 5 and max(nodes.values()) <= NODE_LINES, nodes
    assert shared <= SHARED_NODE_LINES, sizes


def test_the_line_count_skips_blanks_and_comments(tmp_path: Path) -> None:
    module = tmp_path / "m.py"
    module.write_text('"""Doc."""\n\n# note\nx = 1  # set\n    # indented note\n')
    assert _code_lines(module) == 2


DOCS = PACKAGE.parent / "docs"


def _names_used(tree: ast.AST) -> list[str]:
    """Every name a module uses: loads, attributes, imports and identifier strings."""
    out: list[str] = []
    for node in ast.walk(tree):
        if isinstance(node, ast.Name):
            out.append(node.id)
        elif isinstance(node, ast.Attribute):
            out.append(node.attr)
        elif isinstance(node, ast.alias):
            out.append(node.name.rsplit(".", 1)[-1])
        elif isinstance(node, ast.Constant) and isinstance(node.value, str):
            out.append(node.value)
    return out


def unused_public_names(sources: dict[str, str], docs: str) -> list[str]:
    """Public top-level functions and classes nothing in `sources` uses (an `__all__` entry is
    no use) and `docs` does not describe: dead, or helpers only the tests call."""
    trees = {name: ast.parse(text) for name, text in sources.items()}
    used: dict[str, int] = {}
    for tree in trees.values():
        for n in _names_used(tree):
            used[n] = used.get(n, 0) + 1
    out = []
    for module, tree in sorted(trees.items()):
        exported = [
            e.value
            for node in tree.body
            if isinstance(node, ast.Assign)
            and any(isinstance(t, ast.Name) and t.id == "__all__" for t in node.targets)
            and isinstance(node.value, ast.List | ast.Tuple)
            for e in node.value.elts
            if isinstance(e, ast.Constant)
        ]
        for node in tree.body:
            if not isinstance(node, ast.FunctionDef | ast.ClassDef) or node.name.startswith("_"):
                continue
            uses = used.get(node.name, 0) - exported.count(node.name)
            if uses <= 0 and f"`{node.name}" not in docs:
                out.append(f"{module}.{node.name}")
    return out


def test_every_public_function_has_a_caller_or_is_documented() -> None:
    sources = {name: path.read_text() for name, path in _modules().items()}
    docs = "\n".join(p.read_text() for p in sorted(DOCS.glob("*.md")))
    assert unused_public_names(sources, docs) == []


def test_the_unused_name_check_sees_a_helper_only_tests_call() -> None:
    sources = {"m": "def used():\n    pass\n\n\ndef helper():\n    used()\n", "n": "import m\n"}
    assert unused_public_names(sources, "") == ["m.helper"]
    assert unused_public_names(sources, "`helper(x)` does ...") == []


def test_no_module_changes_scikit_learn_s_global_config() -> None:
    """scikit-learn's config is process-wide: a node or library that sets it changes every other
    estimator of the process; `config_context` scopes it to the calls that need it."""
    setters = [
        name
        for name, path in _modules().items()
        if "set_config" in _names_used(ast.parse(path.read_text()))
    ]
    assert setters == []


def foreign_private_writes(source: str) -> list[str]:
    """Assignments to a private attribute (`x._name`) of an object that is neither `self` /
    `cls` nor made in the same method by the enclosing class: another library's internals."""
    found = []
    for cls in (n for n in ast.walk(ast.parse(source)) if isinstance(n, ast.ClassDef)):
        for fn in (n for n in cls.body if isinstance(n, ast.FunctionDef)):
            own = {"self", "cls"}
            for node in ast.walk(fn):
                if isinstance(node, ast.Assign) and isinstance(node.value, ast.Call):
                    made = ast.unparse(node.value.func)
                    if made in (cls.name, "cls", "type(self)"):
                        own |= {t.id for t in node.targets if isinstance(t, ast.Name)}
            found += _private_writes(fn, own)
    return found


def _private_writes(fn: ast.FunctionDef, own: set[str]) -> list[str]:
    out = []
    for node in ast.walk(fn):
        if not isinstance(node, ast.Assign | ast.AugAssign | ast.AnnAssign):
            continue
        targets = node.targets if isinstance(node, ast.Assign) else [node.target]
        for target in (t for tt in targets for t in ast.walk(tt)):
            if (
                isinstance(target, ast.Attribute)
                and target.attr.startswith("_")
                and not target.attr.startswith("__")
                and not (isinstance(target.value, ast.Name) and target.value.id in own)
            ):
                out.append(f"{fn.name}: {ast.unparse(target)}")
    return out


def test_no_module_sets_another_library_s_private_attributes() -> None:
    writes = {
        name: found
        for name, path in _modules().items()
        if (found := foreign_private_writes(path.read_text()))
    }
    assert writes == {}


def test_the_private_write_check_sees_a_foreign_one() -> None:
    source = (
        "class Head:\n"
        "    @classmethod\n"
        "    def load(cls):\n"
        "        head = cls()\n"
        "        head._ok = 1\n"
        "        mr = MiniRocket()\n"
        "        mr._n_jobs = 1\n"
    )
    assert foreign_private_writes(source) == ["load: mr._n_jobs"]
