"""ROS 2 Humble message classes, importable by their ROS names: `from twin.msgs import Twist, LaserScan`.

The classes are rosbags' (its Humble type store) plus nav2_msgs and twin_msgs, so a message built
here is the one a ROS 2 node would send, field for field. A short name resolves to the first
package that defines it, in this order: geometry_msgs, sensor_msgs, nav_msgs, std_msgs,
builtin_interfaces, tf2_msgs, rosgraph_msgs, nav2_msgs, twin_msgs, rcl_interfaces, then the rest
alphabetically (`Path` is nav_msgs/Path, `Time` builtin_interfaces/Time). Full names always work:
`get_message("visualization_msgs/msg/Marker")`.

    from twin.msgs import Header, PoseWithCovarianceStamped, Time
    msg = PoseWithCovarianceStamped(header=Header(stamp=Time(sec=0, nanosec=0), frame_id="map"), ...)

`serialize` and `deserialize` turn messages into CDR bytes and back, as a bag stores them.
"""

from __future__ import annotations

import functools
from typing import TYPE_CHECKING, Any

from twin.core.config import suggest
from twin.core.errors import ConfigError
from twin.core.msgdefs import EXTRA_DEFINITIONS

if TYPE_CHECKING:
    from rosbags.typesys.store import Typestore

__all__ = ["deserialize", "get_message", "message_type_name", "misfit_field", "serialize", "typestore"]

_PACKAGE_ORDER = (
    "geometry_msgs",
    "sensor_msgs",
    "nav_msgs",
    "std_msgs",
    "builtin_interfaces",
    "tf2_msgs",
    "rosgraph_msgs",
    "nav2_msgs",
    "twin_msgs",
    "rcl_interfaces",
)


@functools.cache
def typestore() -> Typestore:
    """Return the type store: ROS 2 Humble's types plus nav2_msgs and twin_msgs (built once)."""
    from rosbags.typesys import Stores, get_types_from_msg, get_typestore

    store = get_typestore(Stores.ROS2_HUMBLE)
    extra: dict[str, Any] = {}
    for name, text in EXTRA_DEFINITIONS.items():
        extra.update(get_types_from_msg(text, name))
    store.register(extra)
    return store


@functools.cache
def _short_names() -> dict[str, str]:
    def rank(msgtype: str) -> tuple[int, str]:
        package = msgtype.split("/", 1)[0]
        order = _PACKAGE_ORDER.index(package) if package in _PACKAGE_ORDER else len(_PACKAGE_ORDER)
        return order, msgtype

    names: dict[str, str] = {}
    for msgtype in sorted((t for t in typestore().types if "/msg/" in t), key=rank):
        names.setdefault(msgtype.rsplit("/", 1)[1], msgtype)
    return names


_DTYPES = {
    "bool": "bool",
    "byte": "uint8",
    "char": "uint8",
    "int8": "int8",
    "uint8": "uint8",
    "int16": "int16",
    "uint16": "uint16",
    "int32": "int32",
    "uint32": "uint32",
    "int64": "int64",
    "uint64": "uint64",
    "float32": "float32",
    "float64": "float64",
}


def _default(desc: tuple[Any, Any]) -> Any:
    """Return a fresh default value for one field description of the type store (rclpy's defaults)."""
    import numpy as np

    kind, args = desc
    if kind == 1:  # a base type: (name, string bound)
        base = args[0]
        return "" if base in ("string", "wstring") else False if base == "bool" else 0.0 if "float" in base else 0
    if kind == 2:  # a message
        return get_message(args)()
    inner, size = args
    if kind == 3 and inner[0] == 1 and inner[1][0] in _DTYPES:  # a fixed array of numbers
        return np.zeros(size, dtype=_DTYPES[inner[1][0]])
    if kind == 3:
        return [_default(inner) for _ in range(size)]
    if inner[0] == 1 and inner[1][0] in _DTYPES:  # a sequence of numbers
        return np.zeros(0, dtype=_DTYPES[inner[1][0]])
    return []


@functools.cache
def _class(msgtype: str) -> type:
    """The message class with rclpy's conveniences: every field optional, with its default."""
    base = typestore().types[msgtype]
    fields: Any = typestore().fielddefs[msgtype][1]
    names = [n for n, _ in fields]
    descs = dict(fields)

    def init(self: Any, *args: Any, **kwargs: Any) -> None:
        for name, value in zip(names, args, strict=False):
            kwargs[name] = value
        for name in names:
            if name not in kwargs:
                kwargs[name] = _default(descs[name])
        base.__init__(self, **kwargs)

    return type(base.__name__, (base,), {"__init__": init, "__doc__": f"ROS 2 message {msgtype}."})


def _normalize(msg: Any, msgtype: str) -> Any:
    """Turn lists given for number arrays into the numpy arrays the serialiser takes (rclpy takes both)."""
    import numpy as np

    fields: Any = typestore().fielddefs[msgtype][1]
    for name, (kind, args) in fields:
        value = getattr(msg, name)
        if kind == 2:
            _normalize(value, args)
        elif kind in (3, 4):
            inner = args[0]
            if inner[0] == 1 and inner[1][0] in _DTYPES and not isinstance(value, np.ndarray):
                setattr(msg, name, np.asarray(value, dtype=_DTYPES[inner[1][0]]))
            elif inner[0] == 2:
                for item in value:
                    _normalize(item, inner[1])
    return msg


_INTEGER_RANGES = {
    "byte": (0, 255),
    "char": (0, 255),
    "int8": (-(1 << 7), (1 << 7) - 1),
    "uint8": (0, (1 << 8) - 1),
    "int16": (-(1 << 15), (1 << 15) - 1),
    "uint16": (0, (1 << 16) - 1),
    "int32": (-(1 << 31), (1 << 31) - 1),
    "uint32": (0, (1 << 32) - 1),
    "int64": (-(1 << 63), (1 << 63) - 1),
    "uint64": (0, (1 << 64) - 1),
}


def misfit_field(msg: Any, msgtype: str, path: str = "") -> str | None:
    """Return the first field whose value its type cannot hold (`linear.x is 'fast' (str), not a float64`), or None.

    What the serialiser only says as "required argument is not a float": said with the field's name,
    its value and the type it needs, for a user's node that filled a message wrongly.
    """
    fields: Any = typestore().fielddefs[msgtype][1]
    for name, (kind, args) in fields:
        where = f"{path}{name}"
        if not hasattr(msg, name):
            return f"{where} is missing"
        value = getattr(msg, name)
        if kind == 1:
            found = _misfit_base(value, args[0], where)
        elif kind == 2:
            if hasattr(value, "__msgtype__"):  # a message (of this type or one with its fields)
                found = misfit_field(value, args, where + ".")
            else:
                found = f"{where} is {value!r} ({type(value).__name__}), not a {args}"
        else:
            found = _misfit_sequence(value, kind, args, where)
        if found is not None:
            return found
    return None


def _misfit_sequence(value: Any, kind: int, args: Any, where: str) -> str | None:
    """A fixed array (kind 3: args (inner, size)) or a sequence (kind 4: (inner, bound)) that does not fit."""
    import numpy as np

    inner, size = args
    if isinstance(value, str | bytes) or not isinstance(value, list | tuple | np.ndarray):
        return f"{where} is {value!r} ({type(value).__name__}), not a sequence"
    if kind == 3 and len(value) != size:
        return f"{where} has {len(value)} items, not the {size} its type fixes"
    if kind == 4 and size and len(value) > size:
        return f"{where} has {len(value)} items, more than its bound {size}"
    if isinstance(value, np.ndarray):
        return None  # the serialiser casts an array's numbers (rclpy takes both)
    for i, item in enumerate(value):
        if inner[0] == 1:
            found = _misfit_base(item, inner[1][0], f"{where}[{i}]")
        else:
            found = misfit_field(item, inner[1], f"{where}[{i}].")
        if found is not None:
            return found
    return None


def _misfit_base(value: Any, base: str, where: str) -> str | None:
    """A number, bool or string field whose value its type cannot hold."""
    import numpy as np

    if base in ("float32", "float64"):
        ok = isinstance(value, int | float | np.integer | np.floating) and not isinstance(value, bool)
    elif base == "bool":
        ok = isinstance(value, bool | np.bool_)
    elif base in ("string", "wstring"):
        ok = isinstance(value, str)
    elif base in _INTEGER_RANGES:
        low, high = _INTEGER_RANGES[base]
        if isinstance(value, int | np.integer) and not isinstance(value, bool) and not low <= value <= high:
            return f"{where} is {value}, outside {base}'s {low} to {high}"
        ok = isinstance(value, int | np.integer) and not isinstance(value, bool)
    else:
        return None
    return None if ok else f"{where} is {value!r} ({type(value).__name__}), not a {base}"


def get_message(name: str) -> type:
    """Return the message class for a short (`Twist`) or full (`geometry_msgs/msg/Twist`) name.

    Raises:
        ConfigError: If no Humble, nav2_msgs or twin_msgs type has that name.
    """
    types = typestore().types
    full = name if "/" in name else _short_names().get(name, "")
    if "/" in name and "/msg/" not in name and name.count("/") == 1:
        full = name.replace("/", "/msg/")  # geometry_msgs/Twist, as ROS 1 and launch files write it
    if full not in types:
        choices = list(_short_names()) if "/" not in name else [t for t in types if "/msg/" in t]
        msg = f"no ROS 2 message type {name!r}{suggest(name, choices)}"
        raise ConfigError(msg)
    return _class(full)


def message_type_name(msg_type: type | str) -> str:
    """Return the full ROS name (`geometry_msgs/msg/Twist`) of a message class or name.

    Raises:
        ConfigError: If the name or class is not a known message type.
    """
    if isinstance(msg_type, str):
        msg_type = get_message(msg_type)
    name = getattr(msg_type, "__msgtype__", None)
    if not isinstance(name, str):
        msg = f"{msg_type!r} is not a ROS 2 message class; import message classes from twin.msgs"
        raise ConfigError(msg)
    return name


def serialize(msg: Any, msgtype: str | None = None) -> bytes:
    """Return a message's CDR bytes (little endian, as rosbag2 stores them)."""
    name = msgtype or msg.__msgtype__
    try:
        return bytes(typestore().serialize_cdr(msg, name))
    except (TypeError, AttributeError, ValueError):
        return bytes(typestore().serialize_cdr(_normalize(msg, name), name))


def deserialize(data: bytes | memoryview, msgtype: str) -> Any:
    """Return the message object of `msgtype` decoded from CDR bytes."""
    return typestore().deserialize_cdr(data, msgtype)


def __getattr__(name: str) -> type:
    if name.startswith("__"):
        raise AttributeError(name)
    try:
        return get_message(name)
    except ConfigError as err:
        raise AttributeError(str(err)) from None
