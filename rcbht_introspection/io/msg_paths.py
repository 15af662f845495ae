"""Field paths into the messages of a bag, `/topic.field.subfield`, checked against its types.

A path is resolved once against the message definitions the bag stores (rosbags' typestore), so
a wrong topic or field is one named error before any message is read. A message type with a
single field stands for that field (std_msgs/String is its `data`), and each path knows the
nearest header on its way (the leaf's own, else the closest enclosing message's) for stamps.
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from rosbags.interfaces import Nodetype

from rcbht_introspection.errors import InputError

WRENCH_STAMPED = "geometry_msgs/msg/WrenchStamped"
WRENCH = "geometry_msgs/msg/Wrench"
HEADER = "std_msgs/msg/Header"
INTEGER_TYPES = frozenset(
    {"int8", "uint8", "int16", "uint16", "int32", "uint32", "int64", "uint64", "byte", "char"}
)
STRING_TYPES = frozenset({"string", "wstring"})

Fielddefs = Mapping[str, tuple[Any, list[tuple[str, tuple[int, Any]]]]]
"""rosbags' Typestore.fielddefs: type name -> (constants, [(field, (node type, argument))])."""


@dataclass(frozen=True)
class FieldPath:
    """A resolved path: its topic, the fields from the message to the leaf, the leaf's type."""

    spec: str
    topic: str
    fields: tuple[str, ...]
    leaf: str
    """A message type name (geometry_msgs/msg/Wrench) or a base type (int32, string)."""
    header: tuple[str, ...] | None
    """Fields from the message to the nearest std_msgs/Header on the way, None if there is none."""

    def value(self, msg: Any) -> Any:
        """The leaf of a message of this path's topic."""
        for name in self.fields:
            msg = getattr(msg, name)
        return msg

    def header_stamp_ns(self, msg: Any) -> int:
        """Stamp (ns) of the nearest header of a message of this path's topic."""
        assert self.header is not None
        for name in self.header:
            msg = getattr(msg, name)
        return int(msg.stamp.sec) * 10**9 + int(msg.stamp.nanosec)

    @property
    def is_integer(self) -> bool:
        return self.leaf in INTEGER_TYPES

    @property
    def is_string(self) -> bool:
        return self.leaf in STRING_TYPES


def topic_listing(topics: Mapping[str, str | None]) -> str:
    """'/a (pkg/msg/A), /b (pkg/msg/B)': the topics of a bag for an error message."""
    return ", ".join(f"{t} ({m or 'several types'})" for t, m in sorted(topics.items())) or "none"


def _fields(fielddefs: Fielddefs, msgtype: str) -> list[tuple[str, tuple[int, Any]]]:
    return fielddefs[msgtype][1]


def _header_field(fielddefs: Fielddefs, msgtype: str) -> str | None:
    """Name of the msgtype's std_msgs/Header field, if it has one."""
    for name, (node, arg) in _fields(fielddefs, msgtype):
        if node == Nodetype.NAME and arg == HEADER:
            return name
    return None


def resolve_path(
    spec: str, topics: Mapping[str, str | None], fielddefs: Fielddefs, bag: Path | str
) -> FieldPath:
    """Resolve `/topic` or `/topic.field.subfield` in a bag, or raise an InputError naming it."""
    topic, fields, msgtype = _topic_of(spec, topics, bag)
    walked, leaf, header = _descend(spec, topic, fields, msgtype, fielddefs, bag)
    walked, leaf, header = _unwrap(walked, leaf, header, fielddefs)
    if leaf == WRENCH_STAMPED:
        header = (*walked, "header")
    return FieldPath(spec, topic, walked, leaf, header)


def _topic_of(
    spec: str, topics: Mapping[str, str | None], bag: Path | str
) -> tuple[str, tuple[str, ...], str]:
    """(topic, field names, message type) of a path: a topic of the bag with one type."""
    if not spec.startswith("/"):
        raise InputError("a topic starts with '/' (`/topic` or `/topic.field`)", bag, field=spec)
    topic, _, rest = spec.partition(".")
    fields = tuple(rest.split(".")) if rest else ()
    if any(not f for f in fields):
        raise InputError("empty field name in the path", bag, field=spec)
    if topic not in topics:
        raise InputError(f"no such topic; the bag has {topic_listing(topics)}", bag, field=spec)
    msgtype = topics[topic]
    if msgtype is None:
        raise InputError("the topic holds messages of several types", bag, field=spec)
    return topic, fields, msgtype


def _descend(
    spec: str,
    topic: str,
    fields: tuple[str, ...],
    msgtype: str,
    fielddefs: Fielddefs,
    bag: Path | str,
) -> tuple[tuple[str, ...], str, tuple[str, ...] | None]:
    """Follow the field names from the topic's type: (fields walked, type reached, path of the
    nearest std_msgs/Header on the way); a missing field or an array is an InputError."""
    leaf: str = msgtype
    header: tuple[str, ...] | None = None
    walked: tuple[str, ...] = ()
    for name in fields:
        if leaf not in fielddefs:  # a base type
            where = ".".join(walked) or topic
            raise InputError(f"{where} is {leaf}, it has no field {name!r}", bag, field=spec)
        own = _header_field(fielddefs, leaf)
        header = (*walked, own) if own else header
        known = dict(_fields(fielddefs, leaf))
        if name not in known:
            names = ", ".join(known) or "none"
            raise InputError(f"no field {name!r} in {leaf} (fields: {names})", bag, field=spec)
        node, arg = known[name]
        if node in (Nodetype.ARRAY, Nodetype.SEQUENCE):
            raise InputError(f"{name!r} is an array; a path cannot go into arrays", bag, field=spec)
        walked = (*walked, name)
        leaf = arg if node == Nodetype.NAME else arg[0]
    return walked, leaf, header


def _unwrap(
    walked: tuple[str, ...], leaf: str, header: tuple[str, ...] | None, fielddefs: Fielddefs
) -> tuple[tuple[str, ...], str, tuple[str, ...] | None]:
    """A message of one field stands for it (std_msgs/String -> data), wrenches stay messages:
    follow such single fields down, noting headers on the way."""
    while leaf in fielddefs and leaf not in (WRENCH, WRENCH_STAMPED):
        own = _header_field(fielddefs, leaf)
        header = (*walked, own) if own else header
        members = _fields(fielddefs, leaf)
        if len(members) != 1 or members[0][1][0] in (Nodetype.ARRAY, Nodetype.SEQUENCE):
            break
        name, (node, arg) = members[0]
        walked = (*walked, name)
        leaf = arg if node == Nodetype.NAME else arg[0]
    return walked, leaf, header
