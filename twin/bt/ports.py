"""Port declarations: what a node type reads and writes, mirroring BT.CPP's `providedPorts()`.

A node class declares its ports by returning them from the classmethod `provided_ports()`:

    class GoToPose(StatefulActionNode):
        @classmethod
        def provided_ports(cls):
            return (input_port("loc", str, required=True), output_port("result"))

Types are `PortType`s or Python classes (see `twin.bt.values.port_type`); `None` is BT.CPP's
`AnyTypeAllowed`. A default is any value with a string form (BT.CPP stores `toStr(default)` and
parses it back when the port is read); an output default must name a blackboard entry (`{key}`).
"""

from __future__ import annotations

import dataclasses
from typing import Any, Final

from twin.bt.status import PortDirection
from twin.bt.values import PortType, port_type, to_str

__all__ = [
    "NO_DEFAULT",
    "POST_CONDITIONS",
    "PRE_CONDITIONS",
    "PortSpec",
    "bidirectional_port",
    "input_port",
    "is_allowed_port_name",
    "is_reserved_attribute",
    "output_port",
]


class _NoDefault:
    __slots__ = ()

    def __repr__(self) -> str:
        return "NO_DEFAULT"


NO_DEFAULT: Final = _NoDefault()

# The order is the evaluation order of BT.CPP (`PreCond`, `PostCond`).
PRE_CONDITIONS: Final = ("_failureIf", "_successIf", "_skipIf", "_while")
POST_CONDITIONS: Final = ("_onHalted", "_onFailure", "_onSuccess", "_post")
_RESERVED: Final = frozenset((*PRE_CONDITIONS, *POST_CONDITIONS, "name", "ID", "_autoremap"))


def is_reserved_attribute(name: str) -> bool:
    """True for attributes the loader handles itself (`name`, `ID`, `_autoremap`, scripts)."""
    return name in _RESERVED


def is_allowed_port_name(name: str) -> bool:
    """BT.CPP's rule: a port name starts with a letter and is not a reserved attribute."""
    return bool(name) and name[0].isalpha() and name not in _RESERVED


@dataclasses.dataclass(frozen=True, kw_only=True, slots=True)
class PortSpec:
    """One port of a node type.

    Attributes:
        name: the XML attribute that sets it.
        direction: input, output or inout.
        type: the declared type.
        default: the default value, or `NO_DEFAULT`.
        default_str: the default as the string the loader puts in the node's config ("" if none).
        description: shown by `twin tree show --models` and written to `<TreeNodesModel>`.
        required: `twin tree validate` reports the port when the XML does not set it (BT.CPP only
            fails when the node reads it).
    """

    name: str
    direction: PortDirection
    type: PortType
    default: Any = NO_DEFAULT
    default_str: str = ""
    description: str = ""
    required: bool = False

    @property
    def is_input(self) -> bool:
        """True for input and inout ports."""
        return self.direction is not PortDirection.OUTPUT

    @property
    def is_output(self) -> bool:
        """True for output and inout ports."""
        return self.direction is not PortDirection.INPUT


def _make(
    direction: PortDirection, name: str, type_: Any, default: Any, description: str, *, required: bool
) -> PortSpec:
    if not is_allowed_port_name(name):
        msg = (
            f"invalid port name {name!r}: a port name starts with a letter and is not "
            f"'name', 'ID' or a reserved '_' attribute"
        )
        raise ValueError(msg)
    default_str = ""
    if default is not NO_DEFAULT:
        default_str = to_str(default) or ""
    return PortSpec(
        name=name,
        direction=direction,
        type=port_type(type_),
        default=default,
        default_str=default_str,
        description=description,
        required=required,
    )


def input_port(
    name: str, type_: Any = None, default: Any = NO_DEFAULT, description: str = "", *, required: bool = False
) -> PortSpec:
    """Declare an input port (BT.CPP `InputPort<T>(name, default, description)`)."""
    return _make(PortDirection.INPUT, name, type_, default, description, required=required)


def output_port(name: str, type_: Any = None, default: Any = NO_DEFAULT, description: str = "") -> PortSpec:
    """Declare an output port; a default must name a blackboard entry such as `{result}`.

    Raises:
        ValueError: If the default is not a `{key}` reference.
    """
    if default is not NO_DEFAULT and not (
        isinstance(default, str) and default.startswith("{") and default.endswith("}")
    ):
        msg = f"output port {name!r}: a default must refer to a blackboard entry, i.e. '{{key}}', got {default!r}"
        raise ValueError(msg)
    return _make(PortDirection.OUTPUT, name, type_, default, description, required=False)


def bidirectional_port(
    name: str, type_: Any = None, default: Any = NO_DEFAULT, description: str = "", *, required: bool = False
) -> PortSpec:
    """Declare an inout port (BT.CPP `BidirectionalPort<T>`)."""
    return _make(PortDirection.INOUT, name, type_, default, description, required=required)
