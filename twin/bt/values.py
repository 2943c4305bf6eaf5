"""Port types and value conversions with BehaviorTree.CPP's rules.

BT.CPP keeps every value in a type-erased `Any`: integers (and bools) as 64-bit integers, floating
point as double, text as a string, anything else as itself. Reading a value as another type goes
through `Any::cast<T>` (numbers convert when no precision is lost; text parses as a number; numbers
print as text, a double with six decimals), and a literal port string goes through
`convertFromString<T>` (integers by prefix, doubles as `strtod` does, bools only as
`true/false/TRUE/FALSE/True/False/1/0`). Both are reproduced here for the value model of this
engine: `None` is an empty entry, `bool`/`int` are integers, `float` is a double, `str` is a string
and any other object is carried as is.

`PortType` names a port's declared C++ type (`int`, `unsigned int`, `double`, `std::string`, ...).
Two entries or ports have the same type when their names are equal.
"""

from __future__ import annotations

import enum
import math
import re
import sys
from collections import deque
from collections.abc import Callable, Mapping
from fractions import Fraction
from typing import Any, ClassVar

from twin.bt.status import NodeStatus

__all__ = [
    "ConversionError",
    "PortType",
    "cast_value",
    "parse_string",
    "port_type",
    "to_str",
    "type_of_value",
    "value_to_string",
]


class ConversionError(ValueError):
    """A value or string cannot be converted to the requested type (BT.CPP throws at this point)."""


_INT64_MIN = -(2**63)
_INT64_MAX = 2**63 - 1
_UINT64_MAX = 2**64 - 1
_DOUBLE_EXACT_MAX = 2**53 - 1

_SIGNED_PREFIX = re.compile(r"-?[0-9]+")
_UNSIGNED_PREFIX = re.compile(r"[0-9]+")
# std::from_chars(double), chars_format::general: no '+', no leading blanks, no hex.
_FROM_CHARS_DOUBLE = re.compile(
    r"-?(?:inf(?:inity)?|nan(?:\([0-9A-Za-z_]*\))?|(?:[0-9]+\.?[0-9]*|\.[0-9]+)(?:[eE][+-]?[0-9]+)?)",
    re.IGNORECASE,
)
# strtod / std::stod: leading blanks, a sign, decimal or hexadecimal, inf and nan.
_STRTOD = re.compile(
    r"\s*([+-]?)(?:(0[xX](?:[0-9a-fA-F]+\.?[0-9a-fA-F]*|\.[0-9a-fA-F]+)(?:[pP][+-]?[0-9]+)?)"
    r"|(inf(?:inity)?|nan(?:\([0-9A-Za-z_]*\))?)"
    r"|((?:[0-9]+\.?[0-9]*|\.[0-9]+)(?:[eE][+-]?[0-9]+)?))",
    re.IGNORECASE,
)


def _from_chars_int(text: str, lo: int, hi: int) -> int:
    """Parse an integer prefix as `std::from_chars` does, then check the bounds of the target."""
    match = (_SIGNED_PREFIX if lo < 0 else _UNSIGNED_PREFIX).match(text)
    if match is None:
        msg = f"Can't convert string [{text}] to integer"
        raise ConversionError(msg)
    value = int(match.group())
    if not lo <= value <= hi:
        msg = f"Value out of bound when converting [{text}] to integer"
        raise ConversionError(msg)
    return value


def _convert_from_string_int(text: str, lo: int, hi: int) -> int:
    """BT.CPP `convertFromString` for integers: an int64 (uint64) prefix, then the target's bounds."""
    if hi == _UINT64_MAX:
        return _from_chars_int(text, 0, _UINT64_MAX)
    value = _from_chars_int(text, _INT64_MIN, _INT64_MAX)
    if not lo <= value <= hi:
        msg = f"Value out of bound when converting [{text}] to integer"
        raise ConversionError(msg)
    return value


def from_chars_double(text: str) -> float:
    """`std::from_chars` for a double (BT.CPP's string to number in `Any`): no range, no value.

    It fails on a literal that overflows to infinity or underflows to zero; a subnormal result passes.
    """
    match = _FROM_CHARS_DOUBLE.match(text)
    if match is None:
        msg = "Any failed string to number conversion"
        raise ConversionError(msg)
    literal = match.group()
    value = float(literal.split("(")[0])
    numeric = literal.lstrip("-")[:1] in "0123456789."  # not inf or nan, which it reads as such
    if numeric and (math.isinf(value) or (value == 0.0 and _nonzero_mantissa(literal))):
        msg = "Any failed string to number conversion"
        raise ConversionError(msg)
    return value


def _nonzero_mantissa(literal: str) -> bool:
    """Whether a decimal or hexadecimal literal's digits before its exponent are not all zero."""
    text = literal.lower().lstrip("+-")
    if text.startswith("0x"):
        return any(ch not in "0." for ch in text[2:].partition("p")[0])
    return any(ch in "123456789" for ch in text.partition("e")[0])


def _exact(literal: str) -> Fraction:
    """The exact value of an unsigned decimal or hexadecimal (`0x1.8p-3`) literal."""
    text = literal.lower()
    if text.startswith("0x"):
        body, _, exponent = text[2:].partition("p")
        whole, _, fraction = body.partition(".")
        return Fraction(int(whole + fraction or "0", 16), 16 ** len(fraction)) * Fraction(2) ** int(exponent or "0")
    return Fraction(text)


def stod_out_of_range(literal: str, value: float) -> bool:
    """Whether `std::stod` refuses this unsigned decimal or hex literal (read as `value`) as out of range.

    glibc's strtod reports ERANGE, and `std::stod` throws, when the literal overflows to infinity, or
    when it is tiny and the result is not exact: tiny meaning its exact value, rounded to 53 bits
    as if the exponent had no bound, is below the smallest normal double ("2.2250738585072012e-308"
    is, though the result rounds up to the smallest normal; "2.22507385850720138e-308" is not). An
    exact zero ("0e-500") and an exact subnormal ("0x1p-1074") are in range.
    """
    if math.isinf(value):
        return True
    smallest = sys.float_info.min
    if abs(value) > smallest:
        return False
    if value == 0.0:
        return _nonzero_mantissa(literal)
    exact = _exact(literal)
    return _rounded_53(exact) < Fraction(smallest) and Fraction(abs(value)) != exact


def _rounded_53(x: Fraction) -> Fraction:
    """`x` (> 0) rounded to 53 significant bits, ties to even, with an unbounded exponent."""
    e = x.numerator.bit_length() - x.denominator.bit_length()
    if x < Fraction(2) ** e:
        e -= 1  # now 2**e <= x < 2**(e + 1)
    scale = Fraction(2) ** (52 - e)
    return Fraction(round(x * scale)) / scale


def _strtod(text: str) -> float:
    """`std::stod`: parse the longest valid prefix after blanks; nothing valid is an error."""
    match = _STRTOD.match(text)
    if match is None:
        msg = f"Can't convert string [{text}] to double (std::stod: invalid argument)"
        raise ConversionError(msg)
    sign, hexa, special, decimal = match.groups()
    if special:
        value = float(special.split("(")[0])
    else:
        literal = hexa or decimal
        try:
            value = float.fromhex(literal) if hexa else float(literal)
        except OverflowError:  # float.fromhex refuses what strtod makes infinite (ERANGE)
            value = math.inf
        if stod_out_of_range(literal, value):
            msg = f"Can't convert string [{text}] to double (std::stod: out of range)"
            raise ConversionError(msg)
    return -value if sign == "-" else value


def _convert_bool(text: str) -> bool:
    if text in ("1", "true", "TRUE", "True"):
        return True
    if text in ("0", "false", "FALSE", "False"):
        return False
    msg = "convertFromString(): invalid bool conversion"
    raise ConversionError(msg)


def _convert_status(text: str) -> NodeStatus:
    try:
        return NodeStatus[text]
    except KeyError:
        msg = f"Cannot convert this to NodeStatus: {text}"
        raise ConversionError(msg) from None


def double_to_string(value: float) -> str:
    """`std::to_string(double)`: six decimals."""
    if math.isnan(value):
        return "-nan" if math.copysign(1.0, value) < 0 else "nan"
    return f"{value:f}"


def value_to_string(value: Any) -> str:
    """Read a stored value as a string (`Any::cast<std::string>`).

    Raises:
        ConversionError: If the entry is empty or holds a non-printable object.
    """
    if isinstance(value, str):
        return value
    if isinstance(value, bool):
        return "1" if value else "0"
    if isinstance(value, int):
        return str(int(value))
    if isinstance(value, float):
        return double_to_string(value)
    if value is None:
        msg = "Any::cast failed because it is empty"
        raise ConversionError(msg)
    msg = f"[Any::convert]: no known safe conversion between [{type_name_of(value)}] and [std::string]"
    raise ConversionError(msg)


def type_name_of(value: Any) -> str:
    """The C++-style type name BT.CPP would report for a stored value."""
    return type_of_value(value).name


class PortType:
    """The declared type of a port or blackboard entry.

    Attributes:
        name: C++-style name, also the identity of the type (`int`, `double`, `std::string`, ...).
        kind: how values convert: `any`, `bt_any`, `string`, `int`, `double`, `bool`, `status`,
            `enum`, `sequence`, `custom`.
        strongly_typed: False for `AnyTypeAllowed` and `BT::Any` (BT.CPP `isStronglyTyped`).
        py_type: the Python class of the values, when there is one.
    """

    __slots__ = ("_parse", "_type_info_converter", "hi", "item", "kind", "lo", "name", "py_type", "strongly_typed")

    ANY: ClassVar[PortType]
    BT_ANY: ClassVar[PortType]
    STRING: ClassVar[PortType]
    INT: ClassVar[PortType]
    UINT: ClassVar[PortType]
    INT64: ClassVar[PortType]
    UINT64: ClassVar[PortType]
    DOUBLE: ClassVar[PortType]
    FLOAT: ClassVar[PortType]
    BOOL: ClassVar[PortType]
    NODE_STATUS: ClassVar[PortType]

    def __init__(
        self,
        name: str,
        kind: str,
        *,
        py_type: type | None = None,
        parse: Callable[[str], Any] | None = None,
        strongly_typed: bool = True,
        lo: int = 0,
        hi: int = 0,
        item: PortType | None = None,
        type_info_converter: bool = True,
    ) -> None:
        self.name = name
        self.kind = kind
        self.py_type = py_type
        self._parse = parse
        self.strongly_typed = strongly_typed
        self.lo = lo
        self.hi = hi
        self.item = item
        # Whether BT.CPP's TypeInfo of the type has a StringConverter. An enum's (NodeStatus) has
        # none: a literal is not checked at load, a string cannot be written into an entry of the
        # type, yet `getInput` still converts a string with `convertFromString<T>` (`convert`).
        self._type_info_converter = type_info_converter and parse is not None

    def __eq__(self, other: object) -> bool:
        return isinstance(other, PortType) and other.name == self.name

    def __hash__(self) -> int:
        return hash(self.name)

    def __repr__(self) -> str:
        return f"PortType({self.name!r})"

    @property
    def has_converter(self) -> bool:
        """True when the type's TypeInfo converts strings (BT.CPP: it has a StringConverter)."""
        return self._type_info_converter

    def parse(self, text: str, enums: Mapping[str, int] | None = None) -> Any:
        """Convert a string to a value of this type (`convertFromString<T>` / `TypeInfo::parseString`).

        Returns `None` (an empty value) for types without a converter, as BT.CPP does.

        Raises:
            ConversionError: If the string does not hold a value of this type.
        """
        if self.kind == "enum" and self.py_type is not None:
            return _parse_enum(self.py_type, text, enums)
        if not self._type_info_converter:
            return None
        return self.convert(text)

    def convert(self, text: str) -> Any:
        """`convertFromString<T>`, which `getInput` uses on a string, also for a type whose TypeInfo has no converter.

        Returns `None` for types without one.

        Raises:
            ConversionError: If the string does not hold a value of this type.
        """
        return None if self._parse is None else self._parse(text)

    @classmethod
    def sequence_of(cls, item: PortType, *, container: str = "std::vector") -> PortType:
        """A `;`-separated list type (`std::vector<T>`, or a shared deque for the Loop nodes).

        Args:
            item: the element type (int, double, bool or string).
            container: `std::vector` (a Python list) or `std::deque` (a shared `collections.deque`).
        """
        if container == "std::deque":
            name = f"std::shared_ptr<std::deque<{item.name}>>"

            def parse_deque(text: str) -> deque[Any]:
                return deque(item.parse(part) for part in split_items(text))

            return cls(name, "sequence", py_type=deque, parse=parse_deque, item=item)
        name = f"std::vector<{item.name}>"

        def parse_list(text: str) -> list[Any]:
            return [item.parse(part) for part in split_items(text)]

        return cls(name, "sequence", py_type=list, parse=parse_list, item=item)


def split_items(text: str) -> list[str]:
    """A `;`-separated list's items as BT.CPP's `splitString` gives them.

    Empty items are kept ("a;;b": three), but a final `;` starts no new one ("a;b;": two, ";": one
    empty item), and an empty string has none.
    """
    if not text:
        return []
    parts = text.split(";")
    if text.endswith(";"):
        parts.pop()
    return parts


def _int_type(name: str, lo: int, hi: int) -> PortType:
    return PortType(name, "int", py_type=int, parse=lambda t: _convert_from_string_int(t, lo, hi), lo=lo, hi=hi)


def _no_converter(text: str) -> Any:
    msg = "You didn't implement the template specialization of convertFromString for this type: BT::Any"
    raise ConversionError(msg)


PortType.ANY = PortType("AnyTypeAllowed", "any", strongly_typed=False)
PortType.BT_ANY = PortType("BT::Any", "bt_any", strongly_typed=False, parse=_no_converter)
PortType.STRING = PortType("std::string", "string", py_type=str, parse=lambda t: t)
PortType.INT = _int_type("int", -(2**31), 2**31 - 1)
PortType.UINT = _int_type("unsigned int", 0, 2**32 - 1)
PortType.INT64 = _int_type("long", _INT64_MIN, _INT64_MAX)
PortType.UINT64 = _int_type("unsigned long", 0, _UINT64_MAX)
PortType.DOUBLE = PortType("double", "double", py_type=float, parse=_strtod)
PortType.FLOAT = PortType("float", "double", py_type=float, parse=_strtod)
PortType.BOOL = PortType("bool", "bool", py_type=bool, parse=_convert_bool)
PortType.NODE_STATUS = PortType(
    "BT::NodeStatus", "status", py_type=NodeStatus, parse=_convert_status, type_info_converter=False
)

_CUSTOM_TYPES: dict[type, PortType] = {}


def _parse_enum(cls: type, text: str, enums: Mapping[str, int] | None) -> Any:
    """An enum port: a scripting-enum name, a member name, or an integer."""
    assert issubclass(cls, enum.Enum)
    if enums is not None and text in enums:
        return cls(enums[text])
    if text in cls.__members__:
        return cls.__members__[text]
    number = _convert_from_string_int(text, -(2**31), 2**31 - 1)
    try:
        return cls(number)
    except ValueError:
        msg = f"{number} is not a value of {cls.__name__}"
        raise ConversionError(msg) from None


def port_type(spec: Any) -> PortType:
    """Normalise a type given by a user: a `PortType`, a Python class, or None (any type).

    `int`, `float`, `str` and `bool` map to BT.CPP's `int`, `double`, `std::string` and `bool`;
    `NodeStatus` and other `enum.Enum` classes convert by member name; any other class is carried as
    is and converts from a string with its `from_string` classmethod when it has one.
    """
    if spec is None or spec is Any:
        return PortType.ANY
    if isinstance(spec, PortType):
        return spec
    builtin = {int: PortType.INT, float: PortType.DOUBLE, str: PortType.STRING, bool: PortType.BOOL}
    if spec in builtin:
        return builtin[spec]
    if spec is NodeStatus:
        return PortType.NODE_STATUS
    if not isinstance(spec, type):
        msg = f"a port type must be a class, a PortType or None, got {spec!r}"
        raise TypeError(msg)
    known = _CUSTOM_TYPES.get(spec)
    if known is None:
        if issubclass(spec, enum.Enum):
            known = PortType(spec.__qualname__, "enum", py_type=spec, parse=None)
        else:
            from_string = getattr(spec, "from_string", None)
            known = PortType(spec.__qualname__, "custom", py_type=spec, parse=from_string)
        _CUSTOM_TYPES[spec] = known
    return known


def type_of_value(value: Any) -> PortType:
    """The type BT.CPP would give a value set with `setOutput<T>` (T from the Python type)."""
    if isinstance(value, str):
        return PortType.STRING
    if isinstance(value, bool):
        return PortType.BOOL
    if isinstance(value, NodeStatus):
        return PortType.NODE_STATUS
    if isinstance(value, int):
        return PortType.INT
    if isinstance(value, float):
        return PortType.DOUBLE
    if value is None:
        return PortType.ANY
    return port_type(type(value))


def parse_string(text: str, ptype: PortType, enums: Mapping[str, int] | None = None) -> Any:
    """Convert a literal port string to `ptype` (`TreeNode::parseString<T>`).

    Untyped ports (`AnyTypeAllowed`) keep the string.

    Raises:
        ConversionError: If the string does not hold a value of the type.
    """
    if ptype.kind == "any":
        return text
    if ptype.kind == "custom" and not ptype.has_converter:
        msg = f"You didn't implement the template specialization of convertFromString for this type: {ptype.name}"
        raise ConversionError(msg)
    if ptype.kind == "status":
        return ptype.convert(text)
    return ptype.parse(text, enums)


def _check_int_range(value: int, ptype: PortType) -> int:
    if ptype.lo >= 0 and value < 0:
        msg = "Value is negative and can't be converted to unsigned"
        raise ConversionError(msg)
    if not ptype.lo <= value <= ptype.hi:
        msg = "Value outside the max numerical limit."
        raise ConversionError(msg)
    return value


def cast_value(value: Any, ptype: PortType) -> Any:
    """Read a stored value as `ptype` (`Any::cast<T>`).

    Raises:
        ConversionError: If the value is empty or no safe conversion exists.
    """
    if value is None:
        msg = "Any::cast failed because it is empty"
        raise ConversionError(msg)
    kind = ptype.kind
    if kind in {"any", "bt_any"}:
        return value
    if kind == "string":
        return value_to_string(value)
    if kind == "int":
        if isinstance(value, str):
            return _from_chars_int(value, ptype.lo, ptype.hi)
        if isinstance(value, int):
            return _check_int_range(int(value), ptype)
        if isinstance(value, float):
            if math.isnan(value) or value != math.floor(value) or not ptype.lo <= value <= ptype.hi:
                msg = "Invalid floating point to integer conversion"
                raise ConversionError(msg)
            return int(value)
    elif kind == "double":
        if isinstance(value, float):
            return value
        if isinstance(value, int):
            if abs(value) > _DOUBLE_EXACT_MAX:
                msg = f"Loss of precision when converting a large integer number to floating point:{value}"
                raise ConversionError(msg)
            return float(value)
        if isinstance(value, str):
            return from_chars_double(value)
    elif kind == "bool":
        if isinstance(value, bool):
            return value
        if isinstance(value, int | float) and value < 0:
            msg = "Value is negative and can't be converted to unsigned"
            raise ConversionError(msg)
        if isinstance(value, int):
            if value not in (0, 1):
                msg = "Implicit casting to bool is not allowed"
                raise ConversionError(msg)
            return bool(value)
        if isinstance(value, float):
            return value != 0.0
    elif kind == "status":
        if isinstance(value, NodeStatus):
            return value
        number: int | None = None
        if isinstance(value, int | float):
            number = int(cast_value(value, PortType.INT))
        elif isinstance(value, str):
            number = _from_chars_int(value, _INT64_MIN, _INT64_MAX)
        if number is not None:
            try:
                return NodeStatus(number)
            except ValueError:
                msg = f"{number} is not a NodeStatus"
                raise ConversionError(msg) from None
    elif kind == "enum" and ptype.py_type is not None:
        if isinstance(value, ptype.py_type):
            return value
        if isinstance(value, int | float | str) and not isinstance(value, bool):
            number = (
                _from_chars_int(value, _INT64_MIN, _INT64_MAX)
                if isinstance(value, str)
                else int(cast_value(value, PortType.INT))
            )
            try:
                return ptype.py_type(number)
            except ValueError:
                msg = f"{number} is not a value of {ptype.name}"
                raise ConversionError(msg) from None
    elif ptype.py_type is not None and isinstance(value, ptype.py_type):
        return value
    msg = f"[Any::convert]: no known safe conversion between [{type_name_of(value)}] and [{ptype.name}]"
    raise ConversionError(msg)


def to_str(value: Any) -> str | None:
    """BT.CPP `toStr<T>`, used for the string form of port defaults; None when there is none."""
    if isinstance(value, str):
        return value
    if isinstance(value, bool):
        return "true" if value else "false"
    if isinstance(value, enum.Enum):
        return value.name
    if isinstance(value, int):
        return str(value)
    if isinstance(value, float):
        return double_to_string(value)
    return None


def is_number(value: Any) -> bool:
    """True for integers, bools, int enums and doubles (BT.CPP `Any::isNumber`)."""
    return isinstance(value, int | float)


def is_safe_cast(target: PortType, value: int | float) -> bool:
    """BT.CPP `isCastingSafe`: can a number be stored in an entry of another arithmetic type."""
    if target.kind == "int":
        if isinstance(value, float):
            return not math.isnan(value) and value == math.floor(value) and target.lo <= value <= target.hi
        return target.lo <= int(value) <= target.hi
    if target.kind == "double":
        return isinstance(value, float) or abs(int(value)) <= _DOUBLE_EXACT_MAX
    if target.kind == "bool":
        return value in (0, 1)
    return False


def copy_into(new: Any, old: Any) -> Any:
    """BT.CPP `Any::copyInto`: store a new value over an old one, keeping the old numeric kind.

    Returns the value to store.

    Raises:
        ConversionError: If the kinds cannot be mixed (e.g. a number over a string).
    """
    if old is None:
        return new
    if isinstance(new, str) and isinstance(old, str):
        return new
    old_num = isinstance(old, int | float)
    new_num = isinstance(new, int | float)
    if old_num and new_num:
        if isinstance(old, float):
            return cast_value(new, PortType.DOUBLE)
        converted = cast_value(new, PortType.INT64)
        return bool(converted) if isinstance(old, bool) and converted in (0, 1) else converted
    if type(new) is type(old):
        return new
    msg = "Any::copyInto fails"
    raise ConversionError(msg)
