"""Config files: YAML in, frozen dataclasses out, every error naming file, line and key.

`load_config(Spec, path, defaults=...)` reads a YAML file, lays it over a packaged defaults file
(mappings merge key by key; a mapping whose `type:` changes, lists and scalars replace), and builds
`Spec` from the result by its type hints. Supported field types: `bool`, `int`, `float`, `str`,
`Path` (relative to the file that set it), `NameOrPath` (a name, or a path relative to that file),
`Literal[...]`, `Enum`, `X | None`, `tuple[X, ...]`,
fixed tuples, `list[X]`, `Mapping[str, X]` / `dict[str, X]`, nested dataclasses, and unions of
dataclasses told apart by a `type: Literal["name"]` field (the variant registry).

Unknown keys fail with a "did you mean" suggestion. Nothing past the loader sees a raw dict.
"""

from __future__ import annotations

import dataclasses
import difflib
import enum
import functools
import os
import re
import sys
import types
import typing
from collections.abc import Mapping, Sequence
from pathlib import Path
from typing import Any, TypeVar

import yaml

from twin.core.errors import ConfigError, TwinError
from twin.core.files import read_input
from twin.core.numbers import number_problem
from twin.core.yaml_numbers import compose

__all__ = [
    "ConfigNode",
    "FieldError",
    "NameOrPath",
    "build",
    "key_location",
    "load_config",
    "load_yaml",
    "location",
    "merge",
    "read_text_file",
    "suggest",
]

T = TypeVar("T")

ConfigNode = yaml.Node

_CONSTRUCTOR = yaml.constructor.SafeConstructor()
# A YAML file larger than this is no configuration (the largest shipped is a few kB).
_MAX_TEXT_BYTES = 64 * 2**20


class NameOrPath(str):
    """A value that is a name looked up elsewhere (a model on the model path) or a path to a file or folder.

    A path-like value (it has a `/`, starts with `.` or `~`, or ends in `.sdf`/`.world`) is relative to
    the file that set it, as a `Path` is, when the file or folder is there; anything else stays as
    written (a name, or a path the loader looks up and names in its error).
    """

    __slots__ = ()

    @classmethod
    def beside(cls, value: str, folder: Path) -> NameOrPath:
        """`value`, made absolute against `folder` when it is a path-like value that names something there."""
        if not _path_like(value) or value.startswith("model://"):
            return cls(value)
        try:
            path = Path(value).expanduser()
        except RuntimeError:  # `~nosuchuser/...`: left as written, for the loader to name
            return cls(value)
        if path.is_absolute():
            return cls(os.path.normpath(path))
        beside = folder / path
        # absolute, as a `Path` is: a run's recorded scenario (`--from-bag`) finds it from any folder
        return cls(os.path.abspath(beside)) if beside.exists() else cls(value)


def _path_like(value: str) -> bool:
    return "/" in value or "\\" in value or value.startswith((".", "~")) or value.endswith((".sdf", ".world"))


class FieldError(ValueError):
    """A dataclass's own check about one of its keys (`robots[1].name`), so the message names its line.

    Args:
        path: The key below the dataclass: names of mapping keys and indexes of list items, e.g.
            `("robots", 1, "name")`. Where the file leaves the last keys out (a default), the
            message names the deepest one it has.
        message: What is wrong and the fix.
    """

    def __init__(self, path: tuple[str | int, ...], message: str) -> None:
        super().__init__(message)
        self.path = path


def suggest(word: str, choices: Sequence[str]) -> str:
    """Return `; did you mean 'x'?` for the closest choice, or a list of the valid ones.

    Settings carry their unit in the name (`x_m`, `yaw_rad`), so `x` is matched to `x_m` first.
    """
    with_unit = [c for c in choices if c.startswith(f"{word}_")]
    if len(with_unit) == 1:
        return f"; did you mean {with_unit[0]!r}? (settings name their unit)"
    close = difflib.get_close_matches(word, list(choices), n=1, cutoff=0.6)
    if close:
        return f"; did you mean {close[0]!r}?"
    if choices:
        return f"; valid: {', '.join(sorted(choices))}"
    return ""


def location(node: yaml.Node) -> str:
    """Return `file:line` of a node (1-based line)."""
    mark = node.start_mark
    return f"{mark.name}:{mark.line + 1}"


_KEY_PART = re.compile(r"([^.\[\]]+)|\[(\d+)\]")


def key_location(path: Path, key: str, *, value: object = None) -> str:
    """`FILE:LINE` of a dotted key (`robots[1].drive.fmu`) where the scenario file sets it, else `FILE`.

    A key the file leaves to the defaults has no line of its own; a key inside a list entry the
    file gives is found in it (the entry's own line for a key it inherits). With `value`, a line
    whose text is another value (the run's came from a command-line option) is not named.
    """
    try:
        node: yaml.Node | None = load_yaml(path)
    except (TwinError, OSError):  # (the loader names an unreadable file itself)
        return str(path)
    line = None
    for name, index in _KEY_PART.findall(key):
        if isinstance(node, yaml.MappingNode) and name:
            node = next((v for k, v in node.value if getattr(k, "value", None) == name), None)
        elif isinstance(node, yaml.SequenceNode) and index:
            node = node.value[int(index)] if int(index) < len(node.value) else None
        else:
            node = None
        if node is None:
            break
        line = node.start_mark.line + 1
    if value is not None and isinstance(node, yaml.ScalarNode) and node.value != str(value):
        return str(path)  # the value came from elsewhere (a command-line option): not this line's
    return f"{path}:{line}" if line is not None and node is not None else str(path)


def read_text_file(path: Path, error: type[TwinError], *, what: str) -> str:
    """Read a text file as UTF-8, every failure one `error` line naming the file.

    Args:
        path: The file.
        error: The `TwinError` subclass to raise (its exit code tells the file's role).
        what: What the file should be, for the message (e.g. "a UTF-8 YAML file").
    """
    try:
        data = read_input(path, max_bytes=_MAX_TEXT_BYTES)
    except FileNotFoundError:
        msg = f"{path}: file not found"
        raise error(msg) from None
    except IsADirectoryError:
        msg = f"{path}: is a folder; give {what}"
        raise error(msg) from None
    except OSError as err:
        msg = f"{path}: cannot read ({err.strerror})"
        raise error(msg) from None
    if b"\0" in data[:8192]:
        msg = f"{path}: is a binary file, not {what}"
        raise error(msg)
    try:
        return data.decode("utf-8")
    except UnicodeDecodeError as err:
        line = data[: err.start].count(b"\n") + 1
        msg = f"{path}:{line}: not UTF-8 (byte 0x{data[err.start]:02x} at offset {err.start}); save it as UTF-8"
        raise error(msg) from None


def load_yaml(path: Path) -> yaml.Node:
    """Read a YAML file into a node tree that keeps file and line of every value.

    Raises:
        ConfigError: If the file cannot be read or is not valid YAML.
    """
    text = read_text_file(path, ConfigError, what="a UTF-8 YAML file")
    try:
        node = compose(text, str(path))
    except yaml.MarkedYAMLError as err:
        mark = err.problem_mark or err.context_mark
        where = f"{path}:{mark.line + 1}:{mark.column + 1}" if mark else str(path)
        msg = f"{where}: invalid YAML: {err.problem or err.context}"
        raise ConfigError(msg) from None
    except yaml.YAMLError as err:  # e.g. a control character the reader refuses
        msg = f"{path}: invalid YAML: {err}"
        raise ConfigError(" ".join(msg.split())) from None
    except RecursionError:
        msg = f"{path}: the YAML is nested too deeply to read (more than ~{sys.getrecursionlimit() // 4} levels)"
        raise ConfigError(msg) from None
    if node is None:
        node = yaml.MappingNode("tag:yaml.org,2002:map", [])
        node.start_mark = yaml.Mark(str(path), 0, 0, 0, "", 0)
    _refuse_repeated_keys(node)
    _merge_keys(node)
    return node


def _merge_keys(root: yaml.Node) -> None:
    """Lay out YAML merge keys (`<<: *defaults`) in place, as a YAML loader does: the mapping's own keys win.

    Raises:
        ConfigError: A `<<` whose value is not a mapping or a list of mappings (file and line).
    """
    stack, done = [root], set()
    while stack:
        node = stack.pop()
        if id(node) in done:
            continue
        done.add(id(node))
        if isinstance(node, yaml.SequenceNode):
            stack.extend(node.value)
            continue
        if not isinstance(node, yaml.MappingNode):
            continue
        merged: list[tuple[yaml.Node, yaml.Node]] = []
        own: list[tuple[yaml.Node, yaml.Node]] = []
        for key, value in node.value:
            if not (isinstance(key, yaml.ScalarNode) and key.value == "<<" and key.tag.endswith(":merge")):
                own.append((key, value))
                continue
            sources = value.value if isinstance(value, yaml.SequenceNode) else [value]
            for source in sources:
                if not isinstance(source, yaml.MappingNode):
                    msg = f"{location(key)}: '<<' (a YAML merge key) takes a mapping or a list of mappings"
                    raise ConfigError(msg)
                _merge_keys(source)
                taken = {k.value for k, _ in merged}
                merged += [(k, v) for k, v in source.value if k.value not in taken]  # the first source wins
        if len(own) != len(node.value):
            keys = {k.value for k, _ in own}
            node.value = [(k, v) for k, v in merged if k.value not in keys] + own
        stack.extend(v for _, v in node.value)


def _refuse_repeated_keys(root: yaml.Node) -> None:
    """Refuse a key given twice in one mapping (YAML forbids it; PyYAML kept the last, silently).

    Raises:
        ConfigError: Naming the file and line of the second, and the line of the first.
    """
    stack = [root]
    while stack:
        node = stack.pop()
        if isinstance(node, yaml.MappingNode):
            seen: dict[str, yaml.Node] = {}
            for key, value in node.value:
                if isinstance(key, yaml.ScalarNode) and key.value != "<<":
                    first = seen.get(key.value)
                    if first is not None:
                        msg = (
                            f"{location(key)}: {key.value!r} is given twice in one mapping (first at line "
                            f"{first.start_mark.line + 1}); keep one"
                        )
                        raise ConfigError(msg)
                    seen[key.value] = key
                stack.append(value)
        elif isinstance(node, yaml.SequenceNode):
            stack.extend(node.value)


def _get(node: yaml.MappingNode, key: str) -> yaml.Node | None:
    for k, v in node.value:
        if k.value == key:
            found: yaml.Node = v
            return found
    return None


def _merge(base: yaml.Node, over: yaml.Node) -> yaml.Node:
    """Lay `over` on `base`: mappings merge unless their `type:` differs; anything else replaces."""
    if not (isinstance(base, yaml.MappingNode) and isinstance(over, yaml.MappingNode)):
        return over
    base_type, over_type = _get(base, "type"), _get(over, "type")
    if over_type is not None and (base_type is None or base_type.value != over_type.value):
        return over
    merged: list[tuple[yaml.Node, yaml.Node]] = []
    over_keys = {k.value: (k, v) for k, v in over.value}
    for k, v in base.value:
        if k.value in over_keys:
            ok, ov = over_keys.pop(k.value)
            merged.append((ok, _merge(v, ov)))
        else:
            merged.append((k, v))
    merged.extend(over_keys.values())
    out = yaml.MappingNode(over.tag, merged)
    out.start_mark, out.end_mark = over.start_mark, over.end_mark
    return out


def merge(base: yaml.Node, over: yaml.Node) -> yaml.Node:
    """Lay `over` on `base` as `load_config` lays a file on its defaults (see the module docstring)."""
    return _merge(base, over)


def load_config(cls: type[T], path: Path, *, defaults: Path | None = None) -> T:
    """Load `cls` from a YAML file laid over an optional defaults file.

    Raises:
        ConfigError: With file, line and key, if the file is unreadable, invalid or does not fit `cls`.
    """
    node = load_yaml(path)
    if defaults is not None:
        node = _merge(load_yaml(defaults), node)
    value: T = build(cls, node, key="")
    return value


def _fail(node: yaml.Node, key: str, problem: str) -> typing.NoReturn:
    where = location(node)
    msg = f"{where}: {key}: {problem}" if key else f"{where}: {problem}"
    raise ConfigError(msg)


# How a message names what a key takes, in the file's terms rather than the Python class's.
_PLAIN_NAMES: dict[Any, str] = {str: "text", float: "a number", int: "a whole number", bool: "true or false"}
_PLAIN_NAMES[Path] = "a path"
_PLAIN_NAMES[NameOrPath] = "a name or a path"


def _describe(tp: Any) -> str:
    if _is_dataclass_type(tp):
        return f"a mapping (keys: {', '.join(_init_fields(tp))})"
    if tp in _PLAIN_NAMES:
        return _PLAIN_NAMES[tp]
    if isinstance(tp, type):
        return tp.__name__
    return str(tp).replace("typing.", "")


def _kind(node: yaml.Node) -> str:
    """What a YAML node is, for 'got ...'."""
    if isinstance(node, yaml.MappingNode):
        return "a mapping"
    if isinstance(node, yaml.SequenceNode):
        return "a list"
    return repr(_CONSTRUCTOR.construct_object(node, deep=True))


def _scalar(node: yaml.Node, key: str) -> Any:
    if not isinstance(node, yaml.ScalarNode):
        kind = "a mapping" if isinstance(node, yaml.MappingNode) else "a list"
        _fail(node, key, f"expected a single value, got {kind}")
    return _CONSTRUCTOR.construct_object(node, deep=True)


def _is_dataclass_type(tp: Any) -> bool:
    return isinstance(tp, type) and dataclasses.is_dataclass(tp)


@functools.cache
def _type_hints(cls: type) -> dict[str, Any]:
    """`typing.get_type_hints(cls)`, evaluated once per class (it compiles every string annotation)."""
    return typing.get_type_hints(cls)


@functools.cache
def _init_fields(cls: type) -> dict[str, dataclasses.Field[Any]]:
    return {f.name: f for f in dataclasses.fields(cls) if f.init}


def _variant_tag(cls: type) -> tuple[str, ...]:
    hints = _type_hints(cls)
    tp = hints.get("type")
    if tp is None or typing.get_origin(tp) is not typing.Literal:
        return ()
    return tuple(str(a) for a in typing.get_args(tp))


def build(tp: Any, node: yaml.Node, *, key: str) -> Any:
    """Build a value of type `tp` from a YAML node (see the module docstring for the types).

    Raises:
        ConfigError: If the node does not fit `tp`; the message names file, line and key.
    """
    origin = typing.get_origin(tp)
    args = typing.get_args(tp)
    if tp is Any:
        return _CONSTRUCTOR.construct_object(node, deep=True)
    if origin in (typing.Union, types.UnionType):
        return _build_union(args, node, key)
    if origin is typing.Literal:
        value = _scalar(node, key)
        if value not in args:
            _fail(node, key, f"{value!r} is not allowed{suggest(str(value), [str(a) for a in args])}")
        return value
    if _is_dataclass_type(tp):
        return _build_dataclass(tp, node, key)
    if origin in (tuple, list, Sequence) or tp in (tuple, list):
        return _build_sequence(tp, origin, args, node, key)
    if origin in (dict, Mapping) or tp is dict:
        return _build_mapping(args, node, key)
    if isinstance(tp, type) and issubclass(tp, enum.Enum):
        value = _scalar(node, key)
        names = [m.value for m in tp]
        if value not in names:
            _fail(node, key, f"{value!r} is not one of the choices{suggest(str(value), [str(n) for n in names])}")
        return tp(value)
    return _build_plain(tp, node, key)


def _build_plain(tp: Any, node: yaml.Node, key: str) -> Any:
    value = _scalar(node, key)
    if tp is bool:
        if not isinstance(value, bool):
            _fail(node, key, f"expected true or false, got {value!r}")
        return value
    if tp is int:
        if isinstance(value, bool) or not isinstance(value, int):
            _fail(node, key, f"expected a whole number, got {value!r}")
        _check_number(value, node, key)
        return value
    if tp is float:
        if isinstance(value, bool) or not isinstance(value, int | float):
            _fail(node, key, f"expected a number, got {value!r}")
        _check_number(value, node, key)
        return float(value)
    if tp is str:
        if value is None or isinstance(value, bool | dict | list):
            _fail(node, key, f"expected text, got {value!r}")
        return str(value)
    if tp is NameOrPath:
        if value is None or isinstance(value, bool | dict | list) or not str(value):
            _fail(node, key, f"expected a name or a path, got {value!r}")
        return NameOrPath.beside(str(value), Path(node.start_mark.name).parent)
    if tp is Path:
        if not isinstance(value, str) or not value:
            _fail(node, key, f"expected a path, got {value!r}")
        path = Path(value).expanduser()
        if not path.is_absolute():
            path = Path(node.start_mark.name).parent / path
        return Path(os.path.normpath(path))
    if tp is type(None):
        if value is not None:
            _fail(node, key, f"expected null, got {value!r}")
        return None
    msg = f"config type {_describe(tp)} is not supported (key {key})"
    raise TypeError(msg)


def _check_number(value: float, node: yaml.Node, key: str) -> None:
    """Every number of a config file is finite and in its unit's range (`twin.core.numbers`)."""
    problem = number_problem(value, key)
    if problem is not None:
        _fail(node, key, problem)


def _build_union(args: tuple[Any, ...], node: yaml.Node, key: str) -> Any:
    if type(None) in args and isinstance(node, yaml.ScalarNode) and node.tag == "tag:yaml.org,2002:null":
        return None
    members = [a for a in args if a is not type(None)]
    if len(members) == 1:
        return build(members[0], node, key=key)
    if all(_is_dataclass_type(m) for m in members):
        tags: dict[str, Any] = {}
        for member in members:
            for tag in _variant_tag(member):
                if tag in tags:
                    msg = f"variant tag {tag!r} is registered twice ({tags[tag].__name__}, {member.__name__})"
                    raise TypeError(msg)
                tags[tag] = member
        if not isinstance(node, yaml.MappingNode):
            _fail(node, key, f"expected a mapping with a 'type:' key ({', '.join(tags)})")
        tag_node = _get(node, "type")
        if tag_node is None:
            _fail(node, key, f"missing 'type:' (one of {', '.join(tags)})")
        tag = str(_scalar(tag_node, f"{key}.type"))
        if tag not in tags:
            _fail(tag_node, f"{key}.type", f"unknown type {tag!r}{suggest(tag, list(tags))}")
        return _build_dataclass(tags[tag], node, key)
    errors: list[str] = []
    for member in members:
        try:
            return build(member, node, key=key)
        except ConfigError as err:
            errors.append(str(err))
    mappings = [k for k, m in enumerate(members) if _is_dataclass_type(m)]
    if isinstance(node, yaml.MappingNode) and len(mappings) == 1:
        raise ConfigError(errors[mappings[0]])  # the only member a mapping can be: its own reason
    plain_first = sorted(members, key=_is_dataclass_type)
    _fail(node, key, f"expected {' or '.join(_describe(m) for m in plain_first)}, got {_kind(node)}")


def _build_sequence(tp: Any, origin: Any, args: tuple[Any, ...], node: yaml.Node, key: str) -> Any:
    if not isinstance(node, yaml.SequenceNode):
        _fail(node, key, "expected a list")
    items = node.value
    if origin is tuple and args and not (len(args) == 2 and args[1] is Ellipsis):
        if len(items) != len(args):
            _fail(node, key, f"expected a list of {len(args)} values, got {len(items)}")
        return tuple(build(a, n, key=f"{key}[{i}]") for i, (a, n) in enumerate(zip(args, items, strict=True)))
    item_tp = args[0] if args else Any
    values = [build(item_tp, n, key=f"{key}[{i}]") for i, n in enumerate(items)]
    return tuple(values) if origin is tuple or tp is tuple else values


def _build_mapping(args: tuple[Any, ...], node: yaml.Node, key: str) -> Any:
    if not isinstance(node, yaml.MappingNode):
        _fail(node, key, "expected a mapping")
    value_tp = args[1] if len(args) == 2 else Any
    out: dict[str, Any] = {}
    for k, v in node.value:
        name = str(_scalar(k, key))
        out[name] = build(value_tp, v, key=f"{key}.{name}" if key else name)
    return types.MappingProxyType(out)


def _one_level_down(hints: dict[str, Any], name: str, key: str) -> str:
    """A hint for a key written a section too high: `robots[1].initial_pose` is `robots[1].robot.initial_pose`.

    Names each section among `hints` (a section's settings and their types) that has the key, or ""
    (also when more than three have it: a list that long helps no one).
    """
    owners = []
    for field, tp in hints.items():
        members = typing.get_args(tp) if typing.get_origin(tp) in (typing.Union, types.UnionType) else (tp,)
        if any(_is_dataclass_type(m) and name in _init_fields(m) for m in members):
            owners.append(f"{key}.{field}.{name}" if key else f"{field}.{name}")
    return f"; did you mean {' or '.join(repr(o) for o in owners)}?" if 0 < len(owners) <= 3 else ""


def _build_dataclass(cls: type, node: yaml.Node, key: str) -> Any:
    if not isinstance(node, yaml.MappingNode):
        _fail(node, key, f"expected {_describe(cls)}, got {_kind(node)}")
    hints = _type_hints(cls)
    fields = _init_fields(cls)
    kwargs: dict[str, Any] = {}
    for k, v in node.value:
        name = str(_scalar(k, key))
        sub = f"{key}.{name}" if key else name
        if name not in fields:
            _fail(k, sub, f"unknown key{_one_level_down(hints, name, key) or suggest(name, list(fields))}")
        if name in kwargs:
            _fail(k, sub, "key given twice")
        kwargs[name] = build(hints[name], v, key=sub)
    missing = [
        n
        for n, f in fields.items()
        if n not in kwargs and f.default is dataclasses.MISSING and f.default_factory is dataclasses.MISSING
    ]
    if missing:
        _fail(node, key, f"missing required key(s): {', '.join(missing)}")
    try:
        return cls(**kwargs)
    except FieldError as err:
        _fail(*_descend(node, key, err.path), str(err))
    except (ValueError, TypeError) as err:
        _fail(node, key, str(err))


def _descend(node: yaml.Node, key: str, path: tuple[str | int, ...]) -> tuple[yaml.Node, str]:
    """The node at `path` below `node` and its key, as deep as the file goes (see `FieldError`)."""
    for step in path:
        if isinstance(step, int) and isinstance(node, yaml.SequenceNode) and 0 <= step < len(node.value):
            node, key = node.value[step], f"{key}[{step}]"
        elif isinstance(step, str) and isinstance(node, yaml.MappingNode):
            found = next((v for k, v in node.value if isinstance(k, yaml.ScalarNode) and k.value == step), None)
            if found is None:
                break
            node, key = found, f"{key}.{step}" if key else step
        else:
            break
    return node, key
