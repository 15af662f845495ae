"""The one reader of config/*.yaml: YAML mappings -> typed config dataclasses, or a one-line error.

Every tunable number lives in one frozen dataclass per concern (taxonomy, stream, segmenter node,
classifier node, simulator, live augmentation); this module checks a YAML mapping against the
dataclass's field types (nested dataclasses, tuples, dicts, Literal choices) and builds the object.
Every error is an InputError naming file, line and field, e.g.
`config/sim/snap.yaml, line 31, field physics.friction: expected a number, got 'abc'`; the lines come
from PyYAML's node marks.
"""

from __future__ import annotations

import dataclasses
import re
import sys
import types
import typing
from collections.abc import Callable, Hashable, Mapping, Sequence
from pathlib import Path
from typing import TYPE_CHECKING, Any, TypeVar

import yaml

from rcbht_introspection.errors import InputError

if TYPE_CHECKING:
    from _typeshed import DataclassInstance

T = TypeVar("T", bound="DataclassInstance")
"""A config class: a dataclass."""

REPO_CONFIG_DIR = Path(__file__).resolve().parents[1] / "config"


def config_path(name: str) -> Path:
    """Path of config/<name>: the source tree's copy, else the installed share/ copy."""
    # installed: <prefix>/lib/pythonX.Y/site-packages/rcbht_introspection/config_files.py beside
    # <prefix>/share/rcbht_introspection/config (colcon, pip --prefix; in a venv <prefix> = sys.prefix)
    share = Path("share", "rcbht_introspection", "config", name)
    here = Path(__file__).resolve().parents
    candidates = [REPO_CONFIG_DIR / name, *([here[4] / share] if len(here) > 4 else [])]
    try:  # the ament index of a sourced ROS workspace (AMENT_PREFIX_PATH)
        from ament_index_python.packages import get_package_share_directory

        candidates.append(Path(get_package_share_directory("rcbht_introspection"), "config", name))
    except Exception:  # no ament_index_python, no AMENT_PREFIX_PATH, or not indexed
        pass
    candidates.append(Path(sys.prefix) / share)
    for path in candidates:
        if path.is_file():
            return path
    raise InputError(f"configuration file {name} not found", path=candidates[0])


class YamlMapping(dict[Any, Any]):
    """A YAML mapping that remembers its own line and each key's line (1-based)."""

    def __init__(self, line: int | None = None) -> None:
        super().__init__()
        self.line = line
        self.lines: dict[Any, int] = {}


class YamlList(list[Any]):
    """A YAML sequence that remembers its own line and each item's line (1-based)."""

    def __init__(self, items: Sequence[Any], line: int | None, lines: list[int]) -> None:
        super().__init__(items)
        self.line = line
        self.lines = lines


class _LineLoader(yaml.SafeLoader):
    """PyYAML's safe loader, building YamlMapping/YamlList so errors can name a line."""


def _construct_mapping(loader: _LineLoader, node: yaml.MappingNode) -> YamlMapping:
    """A mapping with key lines; a key written twice is an error (PyYAML would keep the last).
    Keys merged in (`<<: *anchor`) may be overridden, as YAML's merge key allows."""
    explicit = sum(1 for k, _ in node.value if k.tag != "tag:yaml.org,2002:merge")
    loader.flatten_mapping(node)  # the merged pairs come first, the explicit ones after them
    merged = len(node.value) - explicit
    out = YamlMapping(node.start_mark.line + 1)
    written: set[Hashable] = set()
    for i, (key_node, value_node) in enumerate(node.value):
        key = loader.construct_object(key_node, deep=True)
        if not isinstance(key, Hashable):
            raise yaml.constructor.ConstructorError(
                None, None, "a list or mapping cannot be a key", key_node.start_mark
            )
        if i >= merged:
            if key in written:
                raise yaml.constructor.ConstructorError(
                    None, None, f"duplicate key {key!r}", key_node.start_mark
                )
            written.add(key)
        out[key] = loader.construct_object(value_node, deep=True)
        out.lines[key] = key_node.start_mark.line + 1
    return out


def _construct_sequence(loader: _LineLoader, node: yaml.SequenceNode) -> YamlList:
    """A list with item lines."""
    items = [loader.construct_object(n, deep=True) for n in node.value]
    return YamlList(items, node.start_mark.line + 1, [n.start_mark.line + 1 for n in node.value])


_LineLoader.add_constructor("tag:yaml.org,2002:map", _construct_mapping)
_LineLoader.add_constructor("tag:yaml.org,2002:seq", _construct_sequence)


def read_yaml(path: Path | str) -> Any:
    """The YAML document of `path` (mappings and lists carry lines); None for an empty file."""
    path = Path(path)
    try:
        text = path.read_text(encoding="utf-8")
    except OSError as exc:
        raise InputError(f"cannot read: {exc.strerror}", path=path) from None
    except UnicodeDecodeError:
        raise InputError("cannot read: not UTF-8 text", path=path) from None
    try:
        return yaml.load(text, Loader=_LineLoader)  # a SafeLoader: no arbitrary objects
    except yaml.MarkedYAMLError as exc:
        mark = exc.problem_mark or exc.context_mark
        problem = str(exc.problem or exc.context or "syntax error")
        opened = exc.context_mark
        if exc.problem and exc.context and opened and mark and opened.line != mark.line:
            problem += f" ({exc.context} from line {opened.line + 1})"  # e.g. an unclosed [
        line = None if mark is None else mark.line + 1
        message = f"not valid YAML: {' '.join(problem.split())}"
        raise InputError(message, path=path, line=line) from None
    except yaml.YAMLError as exc:
        raise InputError(f"not valid YAML: {' '.join(str(exc).split())}", path=path) from None


def _line_of(container: Any, key: Any, default: int | None) -> int | None:
    """Line of `key` in a YamlMapping (or of item `key` in a YamlList), else `default`."""
    if isinstance(container, YamlMapping):
        return container.lines.get(key, default)
    if isinstance(container, YamlList) and isinstance(key, int) and 0 <= key < len(container):
        return container.lines[key]
    return default


def _line_at(data: Any, field: str) -> int | None:
    """Line of a dotted field (`physics.friction`, `fractions[1]`) inside `data`, or nearest."""
    line = getattr(data, "line", None)
    node = data
    for part in re.findall(r"[^.\[\]]+", field):
        key: Any = int(part) if isinstance(node, list) and part.isdigit() else part
        line = _line_of(node, key, line)
        try:
            node = node[key]
        except (KeyError, IndexError, TypeError):
            break
    return line


def _show(value: Any) -> str:
    """repr of a value, shortened to keep the message on one short line."""
    text = repr(value)
    return text if len(text) <= 60 else text[:57] + "..."


def choices_text(choices: Sequence[Any]) -> str:
    """`a or b` / `a, b or c`: the allowed values of a Literal field, as errors list them."""
    names = [str(c) for c in choices]
    return names[0] if len(names) == 1 else f"{', '.join(names[:-1])} or {names[-1]}"


def _number_hint(value: Any) -> str:
    """PyYAML (YAML 1.1) reads `1e-4` as text; say how to write it as a number."""
    if isinstance(value, str) and re.fullmatch(r"[-+]?\d+[eE][-+]?\d+", value):
        return f" (YAML reads it as text; write {re.sub(r'[eE]', '.0e', value, count=1)})"
    return ""


def _field_error(message: str, where: str, path: Path | None, line: int | None) -> InputError:
    """The one-line error of a config field (file, line, dotted field name)."""
    return InputError(message, path=path, line=line, field=where)


def _coerce_union(
    value: Any, annotation: Any, where: str, path: Path | None, line: int | None
) -> Any:
    """The first member of a Union (Optional) that accepts the value; else the first error."""
    args = typing.get_args(annotation)
    if value is None and type(None) in args:
        return None
    errors: list[InputError] = []
    for arg in args:
        if arg is type(None):
            continue
        try:
            return _coerce(value, arg, where, path, line)
        except InputError as exc:
            errors.append(exc)
    raise errors[0]


def _coerce_literal(
    value: Any, annotation: Any, where: str, path: Path | None, line: int | None
) -> Any:
    """A Literal choice: equal to an allowed value and of its type (so True is not 1)."""
    args = typing.get_args(annotation)
    if not any(value == a and type(value) is type(a) for a in args):
        raise _field_error(f"expected {choices_text(args)}, got {_show(value)}", where, path, line)
    return value


def _coerce_sequence(
    value: Any, annotation: Any, where: str, path: Path | None, line: int | None
) -> tuple[Any, ...] | list[Any]:
    """A tuple (fixed or `...` length) or list, item by item with the items' own lines."""
    origin = typing.get_origin(annotation)
    if not isinstance(value, (list, tuple)):
        raise _field_error(f"expected a list, got {_show(value)}", where, path, line)
    args = typing.get_args(annotation)
    if origin is tuple and args and args[-1] is not Ellipsis:
        if len(args) != len(value):
            raise _field_error(f"expected {len(args)} items, got {len(value)}", where, path, line)
        item_types = list(args)
    else:
        item_types = [args[0] if args else Any] * len(value)
    items = [
        _coerce(v, a, f"{where}[{i}]", path, _line_of(value, i, line))
        for i, (a, v) in enumerate(zip(item_types, value, strict=True))
    ]
    return tuple(items) if origin is tuple else items


def _coerce_dict(
    value: Any, annotation: Any, where: str, path: Path | None, line: int | None
) -> dict[Any, Any]:
    """A dict, keys and values checked against its type arguments at each key's line."""
    if not isinstance(value, Mapping):
        raise _field_error(f"expected a mapping, got {_show(value)}", where, path, line)
    ktype, vtype = typing.get_args(annotation) or (Any, Any)
    out = {}
    for k, v in value.items():
        at = _line_of(value, k, line)
        out[_coerce(k, ktype, f"{where}.{k}", path, at)] = _coerce(
            v, vtype, f"{where}.{k}", path, at
        )
    return out


def _coerce_scalar(
    value: Any, annotation: Any, where: str, path: Path | None, line: int | None
) -> Any:
    """float (an int is widened; a bool is not a number), int, bool or str; other types as is."""
    if annotation is float:
        if isinstance(value, bool) or not isinstance(value, (int, float)):
            message = f"expected a number, got {_show(value)}{_number_hint(value)}"
            raise _field_error(message, where, path, line)
        return float(value)
    if annotation is int:
        if isinstance(value, bool) or not isinstance(value, int):
            raise _field_error(f"expected an integer, got {_show(value)}", where, path, line)
        return value
    if annotation is bool:
        if not isinstance(value, bool):
            raise _field_error(f"expected true or false, got {_show(value)}", where, path, line)
        return value
    if annotation is str and not isinstance(value, str):
        raise _field_error(f"expected a string, got {_show(value)}", where, path, line)
    return value


def _coerce(value: Any, annotation: Any, where: str, path: Path | None, line: int | None) -> Any:
    """Check and convert one YAML value against a dataclass field annotation."""
    origin = typing.get_origin(annotation)
    if dataclasses.is_dataclass(annotation) and isinstance(annotation, type):
        if not isinstance(value, Mapping):
            raise _field_error(f"expected a mapping, got {_show(value)}", where, path, line)
        return from_mapping(annotation, value, path=path, prefix=f"{where}.", line=line)
    if origin in (typing.Union, types.UnionType):
        return _coerce_union(value, annotation, where, path, line)
    if origin is typing.Literal:
        return _coerce_literal(value, annotation, where, path, line)
    if origin in (tuple, list):
        return _coerce_sequence(value, annotation, where, path, line)
    if origin is dict:
        return _coerce_dict(value, annotation, where, path, line)
    return _coerce_scalar(value, annotation, where, path, line)


def from_mapping(
    cls: type[T],
    data: Mapping[str, Any],
    *,
    path: Path | None = None,
    prefix: str = "",
    line: int | None = None,
) -> T:
    """Build dataclass `cls` from `data`: unknown keys, missing required keys and wrong types are
    one-line errors (with lines when `data` came from read_yaml)."""
    line = getattr(data, "line", None) or line
    hints = typing.get_type_hints(cls)
    fields = {f.name: f for f in dataclasses.fields(cls) if f.init}
    for key in data:
        if key not in fields:
            raise InputError(
                f"unknown key (known: {', '.join(sorted(fields))})",
                path=path,
                line=_line_of(data, key, line),
                field=f"{prefix}{key}",
            )
    for name, f in fields.items():
        required = f.default is dataclasses.MISSING and f.default_factory is dataclasses.MISSING
        if required and name not in data:
            raise InputError("missing required key", path=path, line=line, field=prefix + name)
    kwargs = {
        k: _coerce(v, hints[k], prefix + k, path, _line_of(data, k, line)) for k, v in data.items()
    }
    return cls(**kwargs)


def _section(document: Any, keys: Sequence[str], path: Path) -> Mapping[str, Any]:
    """The mapping at `keys` inside the document (an empty or null section is an empty mapping)."""
    data = YamlMapping() if document is None else document
    line = getattr(data, "line", None)
    for depth, key in enumerate(keys):
        if not isinstance(data, Mapping):
            where = ".".join(keys[:depth]) or None
            raise InputError(
                f"expected a mapping, got {_show(data)}", path=path, line=line, field=where
            )
        if key not in data:
            raise InputError(
                "missing required key", path=path, line=line, field=".".join(keys[: depth + 1])
            )
        line = _line_of(data, key, line)
        data = YamlMapping(line) if data[key] is None else data[key]
    if not isinstance(data, Mapping):
        raise InputError(
            f"expected a mapping, got {_show(data)}",
            path=path,
            line=line,
            field=".".join(keys) or None,
        )
    return data


def _locate(exc: InputError, data: Any, prefix: str, path: Path) -> InputError:
    """A config class's own validation error, given the file, the line and the full field name."""
    if exc.field is None:
        line = exc.line if exc.line is not None else getattr(data, "line", None)
        return dataclasses.replace(exc, path=exc.path or path, line=line)
    line = exc.line if exc.line is not None else _line_at(data, exc.field)
    return dataclasses.replace(exc, path=exc.path or path, line=line, field=prefix + exc.field)


def config_from_document(
    cls: type[T],
    document: Any,
    *,
    path: Path | str,
    section: Sequence[str] = (),
    fixed: Mapping[str, Any] | None = None,
    check: Callable[[T], object] | None = None,
) -> T:
    """Config `cls` from the mapping at `section` of a read_yaml document.

    `fixed` values replace the file's (e.g. a profile's name); `check` is the class's own
    validation, whose InputError (field relative to `cls`) gets the file, line and full field.
    """
    path = Path(path)
    data = _section(document, section, path)
    prefix = "".join(f"{k}." for k in section)
    config = from_mapping(cls, data, path=path, prefix=prefix)
    if fixed:
        config = dataclasses.replace(config, **fixed)
    if check is not None:
        try:
            check(config)
        except InputError as exc:
            raise _locate(exc, data, prefix, path) from None
    return config


def load_config(
    cls: type[T],
    path: Path | str,
    *,
    section: Sequence[str] = (),
    check: Callable[[T], object] | None = None,
) -> T:
    """Config `cls` from a YAML file (the whole file, or the mapping at `section`)."""
    return config_from_document(cls, read_yaml(path), path=path, section=section, check=check)


def load_profile(
    cls: type[T],
    path: Path | str,
    profile: str,
    *,
    kind: str,
    fixed: Mapping[str, Any] | None = None,
    check: Callable[[T], object] | None = None,
) -> T:
    """Config `cls` from `profiles: {<profile>: {...}}` of a YAML file; `kind` names it in errors."""
    document = read_yaml(path)
    profiles = document.get("profiles") if isinstance(document, Mapping) else None
    if not isinstance(profiles, Mapping) or profile not in profiles:
        known = ", ".join(map(str, profiles)) if isinstance(profiles, Mapping) else "none"
        raise InputError(
            f"unknown {kind} profile {profile!r} (known: {known})",
            path=Path(path),
            line=_line_of(document, "profiles", None),
            field="profiles",
        )
    return config_from_document(
        cls, document, path=path, section=("profiles", profile), fixed=fixed, check=check
    )


def only_profile(path: Path | str, *, kind: str) -> str:
    """The name of the one profile of a `profiles:` file (an error names them if there are more)."""
    document = read_yaml(path)
    profiles = document.get("profiles") if isinstance(document, Mapping) else None
    if not isinstance(profiles, Mapping) or len(profiles) != 1:
        names = ", ".join(map(str, profiles)) if isinstance(profiles, Mapping) else "none"
        raise InputError(
            f"expected one {kind} profile, found: {names}; name the profile to use",
            path=Path(path),
            line=_line_of(document, "profiles", None),
            field="profiles",
        )
    return str(next(iter(profiles)))


class _ProfileDumper(yaml.SafeDumper):
    """Safe YAML with mappings as blocks and lists on one line, as config/*.yaml are written."""


_ProfileDumper.add_representer(
    list,
    lambda dumper, data: dumper.represent_sequence("tag:yaml.org,2002:seq", data, flow_style=True),
)


def write_profile(
    path: Path | str, name: str, obj: Any, *, omit: Sequence[str] = (), header: str = ""
) -> Path:
    """Write config dataclass `obj` as `profiles: {name: {...}}` (without the `omit` fields),
    which load_profile reads back to an equal object; `header` becomes leading # comments."""
    path = Path(path)
    fields = {k: v for k, v in to_mapping(obj).items() if k not in omit}
    document = {"profiles": {name: fields}}
    text = yaml.dump(document, Dumper=_ProfileDumper, sort_keys=False, width=100)
    comments = "".join(f"# {line}".rstrip() + "\n" for line in header.splitlines())
    path.parent.mkdir(parents=True, exist_ok=True)
    path.write_text(comments + text, encoding="utf-8")
    return path


def described(default: Any, description: str) -> Any:
    """A dataclass field with a description (a ROS parameter's; tuples and lists become tuples)."""
    if isinstance(default, (list, tuple)):
        value = tuple(default)
        return dataclasses.field(
            default_factory=lambda: value, metadata={"description": description}
        )
    return dataclasses.field(default=default, metadata={"description": description})


def to_mapping(obj: Any) -> dict[str, Any]:
    """Plain-YAML form of a config dataclass (tuples become lists)."""

    def plain(v: Any) -> Any:
        if isinstance(v, (tuple, list)):
            return [plain(x) for x in v]
        if isinstance(v, dict):
            return {k: plain(x) for k, x in v.items()}
        return v

    return {k: plain(v) for k, v in dataclasses.asdict(obj).items()}
