"""Load typed configuration dataclasses from config/*.yaml, with one-line errors for bad fields.

Every tunable number lives in one frozen dataclass per concern (taxonomy, stream, segmenter node,
classifier node, simulator, ...); this module turns a YAML mapping into such an object and back.
"""

from __future__ import annotations

import dataclasses
import sys
import types
import typing
from pathlib import Path
from typing import Any, TypeVar

import yaml

from rcbht_introspection.errors import InputError

T = TypeVar("T")

REPO_CONFIG_DIR = Path(__file__).resolve().parents[1] / "config"


def config_path(name: str) -> Path:
    """Path of config/<name>: the source tree's copy, else the installed share/ copy."""
    # installed: <prefix>/lib/pythonX.Y/site-packages/rcbht_introspection/config.py beside
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


def _coerce(value: Any, annotation: Any, where: str, path: Path | None) -> Any:
    """Check and convert one YAML value against a dataclass field annotation."""
    origin = typing.get_origin(annotation)
    if dataclasses.is_dataclass(annotation) and isinstance(annotation, type):
        if not isinstance(value, dict):
            raise InputError(f"expected a mapping, got {value!r}", path=path, field=where)
        return from_mapping(annotation, value, path=path, prefix=f"{where}.")
    if origin in (typing.Union, types.UnionType):
        args = typing.get_args(annotation)
        if value is None and type(None) in args:
            return None
        errors = []
        for arg in args:
            if arg is type(None):
                continue
            try:
                return _coerce(value, arg, where, path)
            except InputError as exc:
                errors.append(exc)
        raise errors[0]
    if origin is typing.Literal:
        if value not in typing.get_args(annotation):
            raise InputError(
                f"expected one of {typing.get_args(annotation)}, got {value!r}",
                path=path,
                field=where,
            )
        return value
    if origin in (tuple, list):
        if not isinstance(value, (list, tuple)):
            raise InputError(f"expected a list, got {value!r}", path=path, field=where)
        args = typing.get_args(annotation)
        if origin is tuple and args and args[-1] is not Ellipsis:
            if len(args) != len(value):
                raise InputError(
                    f"expected {len(args)} items, got {len(value)}", path=path, field=where
                )
            items = [
                _coerce(v, a, f"{where}[{i}]", path)
                for i, (a, v) in enumerate(zip(args, value, strict=True))
            ]
        else:
            item_type = args[0] if args else Any
            items = [_coerce(v, item_type, f"{where}[{i}]", path) for i, v in enumerate(value)]
        return tuple(items) if origin is tuple else items
    if origin is dict:
        if not isinstance(value, dict):
            raise InputError(f"expected a mapping, got {value!r}", path=path, field=where)
        _, vtype = typing.get_args(annotation) or (Any, Any)
        return {k: _coerce(v, vtype, f"{where}.{k}", path) for k, v in value.items()}
    if annotation is float:
        if isinstance(value, bool) or not isinstance(value, (int, float)):
            raise InputError(f"expected a number, got {value!r}", path=path, field=where)
        return float(value)
    if annotation is int:
        if isinstance(value, bool) or not isinstance(value, int):
            raise InputError(f"expected an integer, got {value!r}", path=path, field=where)
        return value
    if annotation is bool:
        if not isinstance(value, bool):
            raise InputError(f"expected true or false, got {value!r}", path=path, field=where)
        return value
    if annotation is str:
        if not isinstance(value, str):
            raise InputError(f"expected a string, got {value!r}", path=path, field=where)
        return value
    return value


def from_mapping(
    cls: type[T], data: dict[str, Any], *, path: Path | None = None, prefix: str = ""
) -> T:
    """Build dataclass `cls` from `data`; unknown keys and wrong types are one-line errors."""
    hints = typing.get_type_hints(cls)
    fields = {f.name: f for f in dataclasses.fields(cls)}  # type: ignore[arg-type]
    unknown = sorted(set(data) - set(fields))
    if unknown:
        raise InputError(
            f"unknown key (known: {', '.join(sorted(fields))})",
            path=path,
            field=prefix + unknown[0],
        )
    kwargs = {k: _coerce(v, hints[k], prefix + k, path) for k, v in data.items()}
    return cls(**kwargs)


def load_yaml(cls: type[T], path: Path | str, section: str | None = None) -> T:
    """Load `cls` from a YAML file (optionally one top-level section of it)."""
    path = Path(path)
    try:
        data = yaml.safe_load(path.read_text()) or {}
    except OSError as exc:
        raise InputError(f"cannot read: {exc.strerror}", path=path) from None
    except yaml.YAMLError as exc:
        line = getattr(getattr(exc, "problem_mark", None), "line", None)
        raise InputError(
            "not valid YAML", path=path, line=None if line is None else line + 1
        ) from None
    if section is not None:
        if section not in data:
            raise InputError(f"missing section {section!r}", path=path)
        data = data[section]
    if not isinstance(data, dict):
        raise InputError("expected a mapping at the top level", path=path)
    return from_mapping(cls, data, path=path)


def to_mapping(obj: Any) -> dict[str, Any]:
    """Plain-YAML form of a config dataclass (tuples become lists)."""

    def plain(v: Any) -> Any:
        if isinstance(v, (tuple, list)):
            return [plain(x) for x in v]
        if isinstance(v, dict):
            return {k: plain(x) for k, x in v.items()}
        return v

    return {k: plain(v) for k, v in dataclasses.asdict(obj).items()}
