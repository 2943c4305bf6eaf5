"""String conversion and value casting with BT.CPP's rules."""

from __future__ import annotations

import math
from collections import deque

import pytest

from twin.bt import NodeStatus, PortType
from twin.bt.values import ConversionError, cast_value, parse_string, port_type, to_str, value_to_string


@pytest.mark.parametrize(
    ("text", "expected"),
    [("42", 42), ("-7", -7), ("12abc", 12), ("3.9", 3), ("007", 7)],
)
def test_integer_ports_parse_the_leading_digits_like_from_chars(text: str, expected: int) -> None:
    assert parse_string(text, PortType.INT) == expected


@pytest.mark.parametrize("text", ["", "abc", "+5", " 5", "99999999999"])
def test_integer_port_rejects_text_without_leading_digits_or_out_of_range(text: str) -> None:
    with pytest.raises(ConversionError):
        parse_string(text, PortType.INT)


def test_unsigned_port_rejects_negative_values() -> None:
    with pytest.raises(ConversionError):
        parse_string("-1", PortType.UINT)
    assert parse_string("4294967295", PortType.UINT) == 2**32 - 1


@pytest.mark.parametrize(
    ("text", "expected"), [("1.5", 1.5), ("  2e3", 2000.0), ("0x10", 16.0), ("-.5x", -0.5), ("inf", math.inf)]
)
def test_double_ports_parse_like_stod(text: str, expected: float) -> None:
    assert parse_string(text, PortType.DOUBLE) == expected


@pytest.mark.parametrize(("text", "expected"), [("true", True), ("1", True), ("FALSE", False), ("False", False)])
def test_bool_ports_accept_only_the_bt_cpp_spellings(text: str, expected: bool) -> None:
    assert parse_string(text, PortType.BOOL) is expected


@pytest.mark.parametrize("text", ["yes", "tRue", "2", ""])
def test_bool_ports_reject_other_spellings(text: str) -> None:
    with pytest.raises(ConversionError):
        parse_string(text, PortType.BOOL)


def test_status_ports_parse_status_names() -> None:
    assert parse_string("SKIPPED", PortType.NODE_STATUS) is NodeStatus.SKIPPED
    with pytest.raises(ConversionError):
        parse_string("success", PortType.NODE_STATUS)


def test_untyped_port_keeps_the_string() -> None:
    assert parse_string("{not a key}", PortType.ANY) == "{not a key}"


def test_reading_numbers_as_strings_prints_them_as_cpp_does() -> None:
    assert value_to_string(7) == "7"
    assert value_to_string(11.0) == "11.000000"
    assert value_to_string(True) == "1"


def test_casting_a_double_to_int_needs_an_integral_value() -> None:
    assert cast_value(3.0, PortType.INT) == 3
    with pytest.raises(ConversionError):
        cast_value(3.5, PortType.INT)


def test_casting_to_bool_accepts_0_and_1_and_non_negative_doubles() -> None:
    assert cast_value(1, PortType.BOOL) is True
    assert cast_value(0.25, PortType.BOOL) is True
    for bad in (2, -1, -0.5, "true"):
        with pytest.raises(ConversionError):
            cast_value(bad, PortType.BOOL)


def test_casting_an_empty_entry_fails() -> None:
    with pytest.raises(ConversionError, match="empty"):
        cast_value(None, PortType.STRING)


def test_defaults_print_as_bt_cpp_to_str() -> None:
    assert to_str(True) == "true"
    assert to_str(-1) == "-1"
    assert to_str(10.0) == "10.000000"
    assert to_str(NodeStatus.FAILURE) == "FAILURE"
    assert to_str(object()) is None


def test_sequence_types_split_on_semicolons() -> None:
    queue = PortType.sequence_of(PortType.INT, container="std::deque").parse("1;2;3")
    assert queue == deque([1, 2, 3])
    assert PortType.sequence_of(PortType.DOUBLE).parse("0.5;1") == [0.5, 1.0]


def test_python_classes_convert_with_their_from_string() -> None:
    class Speed:
        def __init__(self, mps: float) -> None:
            self.mps = mps

        @classmethod
        def from_string(cls, text: str) -> Speed:
            return cls(float(text.removesuffix("m/s")))

    speed = parse_string("0.2m/s", port_type(Speed))
    assert isinstance(speed, Speed)
    assert speed.mps == 0.2


def test_python_classes_without_from_string_cannot_be_literals() -> None:
    class Opaque:
        pass

    with pytest.raises(ConversionError, match="convertFromString"):
        parse_string("x", port_type(Opaque))
