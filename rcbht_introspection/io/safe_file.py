"""The safe file under both model files (sub-task model, verifier): loading never executes code.

A NumPy .npz read with allow_pickle=False: a JSON header (format name and version, a SHA-256 over
all content) and plain arrays, written atomically.
"""

from __future__ import annotations

import hashlib
import json
import os
import threading
import zipfile
import zlib
from pathlib import Path
from typing import Any

import numpy as np

from rcbht_introspection.errors import InputError


def checksum(header: dict[str, Any], arrays: dict[str, np.ndarray]) -> str:
    """SHA-256 over the header (without its checksum) and every array's name, dtype, shape, bytes."""
    digest = hashlib.sha256()
    digest.update(
        json.dumps({k: v for k, v in header.items() if k != "checksum"}, sort_keys=True).encode()
    )
    for name in sorted(arrays):
        value = np.ascontiguousarray(arrays[name])
        digest.update(f"{name}|{value.dtype.str}|{value.shape}".encode())
        digest.update(value.tobytes())
    return digest.hexdigest()


def write_safe_npz(
    path: Path, header: dict[str, Any], arrays: dict[str, np.ndarray], compress: bool = True
) -> None:
    """Write a JSON header (with the checksum added) and plain arrays as .npz, atomically: to a
    temporary file beside `path`, then renamed over it. `compress=False` stores the arrays
    uncompressed (larger, but written and read faster); readers take either."""
    header["checksum"] = checksum(header, arrays)
    payload = {"header": np.frombuffer(json.dumps(header).encode(), dtype=np.uint8), **arrays}
    path.parent.mkdir(parents=True, exist_ok=True)
    tmp = path.with_name(f".{path.name}.{os.getpid()}.{threading.get_ident()}.tmp")
    try:
        with tmp.open("wb") as handle:
            # numpy's stub has a bool `allow_pickle` keyword beside **arrays, so mypy takes any
            # str-keyed ** dict as possibly feeding it; the keys here are array names
            write = np.savez_compressed if compress else np.savez
            write(handle, **payload)  # type: ignore[arg-type]
            handle.flush()
            os.fsync(handle.fileno())
        os.replace(tmp, path)
    except BaseException:
        tmp.unlink(missing_ok=True)
        raise


def read_safe_npz(path: Path, kind: str) -> tuple[dict[str, Any], dict[str, np.ndarray]]:
    """(header, arrays) of a file written by write_safe_npz, without its format check; any
    unreadable, header-less or non-JSON file is a one-line InputError naming `kind`."""
    try:
        with np.load(path, allow_pickle=False) as npz:
            arrays = {name: npz[name] for name in npz.files}
    except FileNotFoundError:
        raise InputError(f"{kind} file not found", path) from None
    except (OSError, ValueError, zipfile.BadZipFile, EOFError, zlib.error) as exc:
        raise InputError(f"not a readable {kind} file ({type(exc).__name__})", path) from None
    if "header" not in arrays:
        raise InputError(f"not an rcbht {kind} file (no header)", path)
    try:
        header = json.loads(arrays.pop("header").tobytes().decode())
    except (UnicodeDecodeError, json.JSONDecodeError):
        raise InputError(f"{kind} header is not valid JSON", path, field="header") from None
    if not isinstance(header, dict):
        raise InputError(f"{kind} header is not a mapping", path, field="header")
    return header, arrays


def check_checksum(
    header: dict[str, Any], arrays: dict[str, np.ndarray], path: Path, kind: str
) -> None:
    """One-line InputError when the file's content does not match its checksum."""
    if header.get("checksum") != checksum(header, arrays):
        raise InputError(
            f"checksum mismatch: the {kind} file is corrupt or was modified", path, field="checksum"
        )


def read_checked(
    path: Path, kind: str, form: str, version: int, retrain: str
) -> tuple[dict[str, Any], dict[str, np.ndarray]]:
    """(header, arrays) of a `kind` file of format `form` and `version`, its checksum verified;
    anything else is a one-line InputError (`retrain`: the command that writes a current one)."""
    header, arrays = read_safe_npz(path, kind)
    if header.get("format") != form:
        raise InputError(f"not an rcbht {kind} file", path, field="format")
    if header.get("format_version") != version:
        raise InputError(
            f"{kind} format version {header.get('format_version')!r} is not supported "
            f"(this version reads {version}); retrain with `{retrain}`",
            path,
            field="format_version",
        )
    check_checksum(header, arrays, path, kind)
    return header, arrays
