"""XML reading for SDF: lxml in, a small immutable node tree out, every error naming file:line.

`XmlNode` keeps what the loader and later readers need (tag, attributes, text, children and the
source line) so plugins, sensors and unknown elements can be kept as data without lxml leaking out
of this module.
"""

from __future__ import annotations

import math
import re
from collections.abc import Iterator
from dataclasses import dataclass
from pathlib import Path

import numpy as np
from lxml import etree

from twin.core.errors import WorldError
from twin.core.files import read_input
from twin.core.geometry import Mat4, Pose, matrix_from_pose

__all__ = ["FarPoseError", "XmlNode", "parse_file", "parse_string"]

# An SDF, URDF or model.config larger than this is no description (the largest real worlds are a few MB).
_MAX_XML_BYTES = 256 * 2**20
_EYE4 = np.eye(4)  # copied: faster than np.eye for the many small matrices of a big world


@dataclass(frozen=True, kw_only=True, slots=True)
class XmlNode:
    """One XML element: tag, attributes, stripped text, children, and where it came from."""

    tag: str
    attrib: tuple[tuple[str, str], ...] = ()
    text: str = ""
    children: tuple[XmlNode, ...] = ()
    file: Path | None = None
    line: int = 0

    @property
    def where(self) -> str:
        """Return `file:line` of this element (for messages)."""
        return f"{self.file}:{self.line}" if self.file is not None else f"<string>:{self.line}"

    def get(self, name: str, default: str | None = None) -> str | None:
        """Return an attribute's value, or `default`."""
        for key, value in self.attrib:
            if key == name:
                return value
        return default

    def find(self, tag: str) -> XmlNode | None:
        """Return the first child with this tag, or None."""
        for child in self.children:
            if child.tag == tag:
                return child
        return None

    def findall(self, tag: str) -> Iterator[XmlNode]:
        """Yield every child with this tag, in document order."""
        return (child for child in self.children if child.tag == tag)

    def path(self, path: str) -> XmlNode | None:
        """Return the element at a slash-separated path of child tags, or None."""
        node: XmlNode | None = self
        for part in path.split("/"):
            if node is None:
                return None
            node = node.find(part)
        return node

    def text_at(self, path: str, default: str | None = None) -> str | None:
        """Return the text of the element at `path`, or `default` if it is absent."""
        node = self.path(path)
        return node.text if node is not None else default

    def float_at(self, path: str, default: float) -> float:
        """Return the number at `path`, or `default` if absent.

        Raises:
            WorldError: If the element exists but is not a number.
        """
        node = self.path(path)
        if node is None or node.text == "":
            return default
        return node.as_float()

    def bool_at(self, path: str, default: bool) -> bool:
        """Return the SDF boolean at `path` (`1`/`true` or `0`/`false`), or `default`."""
        node = self.path(path)
        if node is None or node.text == "":
            return default
        return node.as_bool()

    def as_float(self) -> float:
        """Return this element's text as a number.

        Raises:
            WorldError: If it is not one.
        """
        try:
            return float(self.text)
        except ValueError:
            msg = f"{self.where}: <{self.tag}> must be a number, got {self.text!r}"
            raise WorldError(msg) from None

    def as_bool(self) -> bool:
        """Return this element's text as an SDF boolean.

        Raises:
            WorldError: If it is not `true`, `false`, `1` or `0`.
        """
        value = self.text.strip().lower()
        if value in ("1", "true"):
            return True
        if value in ("0", "false"):
            return False
        msg = f"{self.where}: <{self.tag}> must be true/false or 1/0, got {self.text!r}"
        raise WorldError(msg)

    def as_floats(self, count: int | None = None) -> tuple[float, ...]:
        """Return this element's text as whitespace-separated numbers.

        Raises:
            WorldError: If a value is not a number or the count is wrong.
        """
        try:
            values = tuple(map(float, self.text.split()))
        except ValueError:
            msg = f"{self.where}: <{self.tag}> must be numbers, got {self.text!r}"
            raise WorldError(msg) from None
        if count is not None and len(values) != count:
            msg = f"{self.where}: <{self.tag}> needs {count} numbers, got {len(values)} ({self.text!r})"
            raise WorldError(msg)
        return values

    def to_xml(self, indent: str = "") -> str:
        """Return the element as XML text (for plugins and unknown elements kept as data)."""
        attrs = "".join(f' {k}="{_escape(v)}"' for k, v in self.attrib)
        if not self.children:
            if self.text:
                return f"{indent}<{self.tag}{attrs}>{_escape(self.text)}</{self.tag}>"
            return f"{indent}<{self.tag}{attrs}/>"
        inner = "\n".join(child.to_xml(indent + "  ") for child in self.children)
        text = f"{_escape(self.text)}" if self.text else ""
        return f"{indent}<{self.tag}{attrs}>{text}\n{inner}\n{indent}</{self.tag}>"


def _escape(text: str) -> str:
    return text.replace("&", "&amp;").replace("<", "&lt;").replace(">", "&gt;").replace('"', "&quot;")


def _convert(root: etree._Element, file: Path | None, line_offset: int = 0) -> XmlNode:
    # The hot part of loading a big world: children are filtered in lxml (elements only: no
    # comments, processing instructions or entities), lists are built by comprehension.
    only_elements = etree.Element

    def convert(elem: etree._Element) -> XmlNode:
        attrib = elem.attrib
        return XmlNode(
            tag=elem.tag,
            attrib=tuple(attrib.items()) if attrib else (),
            text=(elem.text or "").strip(),
            children=tuple([convert(child) for child in elem.iterchildren(only_elements)]),
            file=file,
            line=(elem.sourceline or 0) + line_offset,
        )

    return convert(root)


def _parser() -> etree.XMLParser:
    # A parser per document: its error log then holds that document's problems only. `recover`
    # keeps going past the slips Gazebo's own XML reader (tinyxml2) never checks; `_parse` still
    # refuses every other error.
    return etree.XMLParser(remove_comments=True, remove_pis=True, resolve_entities=False, huge_tree=True, recover=True)


#: libxml2 errors that tinyxml2, and so Gazebo, lets through: prefixes never declared with xmlns
#: (`<gz:system_priority>`, `<experimental:params>`, SDF's custom elements) and `--` inside a comment.
_TOLERATED_TYPES = frozenset({"ERR_HYPHEN_IN_COMMENT"})
_TOLERATED_DOMAINS = frozenset({"NAMESPACE"})


#: An `&` that starts no entity or character reference (`portal, door & car`).
_BARE_AMPERSAND = re.compile(rb"&(?!(?:[A-Za-z_:][\w.:-]*|#[0-9]+|#x[0-9A-Fa-f]+);)")


def parse_file(path: Path, *, bare_ampersands: bool = False) -> XmlNode:
    """Read an XML file into an `XmlNode` tree.

    Args:
        path: The file.
        bare_ampersands: Read an `&` that starts no entity as the character itself, as tinyxml2
            does (for model.config, whose free-text `<description>` often has one).

    Raises:
        WorldError: If the file cannot be read or is not well-formed XML (with line and column).
    """
    try:
        data = read_input(path, max_bytes=_MAX_XML_BYTES)
    except OSError as err:
        msg = f"{path}: cannot read: {err.strerror or err}"
        raise WorldError(msg) from None
    if bare_ampersands:
        data = _BARE_AMPERSAND.sub(b"&amp;", data)
    return _parse(data, path)


def parse_string(text: str, source: Path | None = None) -> XmlNode:
    """Parse XML text into an `XmlNode` tree (for tests and generated SDF).

    Raises:
        WorldError: If the text is not well-formed XML.
    """
    return _parse(text.encode(), source)


def _parse(data: bytes, path: Path | None) -> XmlNode:
    """Parse as Gazebo does: well-formed XML, forgiving only what tinyxml2 forgives.

    Beyond undeclared prefixes and `--` in comments, blank lines before the XML declaration are
    accepted (they are cut, and line numbers still count them).
    """
    where = str(path) if path is not None else "<string>"
    body = data.lstrip()
    if not body:
        msg = f"{where}: the file is empty; expected an SDF document (<sdf version=...>)"
        raise WorldError(msg)
    skipped_lines = data[: len(data) - len(body)].count(b"\n")
    parser = _parser()
    try:
        root = etree.fromstring(body, parser)
    except etree.XMLSyntaxError as err:
        line, column = err.position if err.position else (err.lineno or 0, 0)
        reason = (err.msg or str(err)).split(", line ")[0]
        msg = f"{where}:{line + skipped_lines}:{column}: malformed XML: {reason}"
        raise WorldError(msg) from None
    for entry in parser.error_log:
        if entry.domain_name in _TOLERATED_DOMAINS or entry.type_name in _TOLERATED_TYPES:
            continue
        reason = entry.message.strip()
        msg = f"{where}:{entry.line + skipped_lines}:{entry.column}: malformed XML: {reason}"
        raise WorldError(msg)
    if root is None:
        msg = f"{where}:1:0: malformed XML: no root element"
        raise WorldError(msg)
    return _convert(root, path, skipped_lines)


_FARTHEST_M = 1e7
"""The farthest a `<pose>` may place anything, m: the bound `twin.core.numbers` sets on every scenario distance."""


class FarPoseError(WorldError):
    """A `<pose>` farther than `_FARTHEST_M`: a world leaves out the model it places (one fallen out of it)."""

    def __init__(self, where: str, distance_m: float) -> None:
        self.where = where
        self.distance_m = distance_m
        super().__init__(
            f"{where}: <pose> puts something {distance_m:g} m from its frame's origin; no world is larger than 1e7 m"
        )


def parse_pose(node: XmlNode | None) -> Mat4:
    """Return the 4x4 matrix of an SDF `<pose>` (identity when absent or empty).

    Accepts `x y z roll pitch yaw` (radians, or degrees with `degrees="true"`) and, from SDF 1.9,
    `rotation_format="quat_xyzw"` with `x y z qx qy qz qw`.

    Raises:
        WorldError: If the numbers are malformed.
    """
    if node is None or not node.text:
        return _EYE4.copy()
    values = node.as_floats()
    if not all(math.isfinite(v) for v in values):
        msg = f"{node.where}: <pose> has a non-finite number: {node.text!r}"
        raise WorldError(msg)
    far = next((v for v in values[:3] if abs(v) > _FARTHEST_M), None)
    if far is not None:  # (its float would not hold a millimetre, and the map and scans overflow)
        raise FarPoseError(node.where, far)
    fmt = node.get("rotation_format", "euler_rpy")
    if fmt == "quat_xyzw":
        if len(values) != 7:
            msg = (
                f"{node.where}: <pose rotation_format='quat_xyzw'> needs 7 numbers (x y z qx qy qz qw), "
                f"got {len(values)}"
            )
            raise WorldError(msg)
        return _matrix_from_quat(values[:3], values[3:])
    if len(values) != 6:
        msg = f"{node.where}: <pose> needs 6 numbers (x y z roll pitch yaw), got {len(values)}: {node.text!r}"
        raise WorldError(msg)
    x, y, z, roll, pitch, yaw = values
    if (node.get("degrees", "false") or "").lower() in ("true", "1"):
        roll, pitch, yaw = math.radians(roll), math.radians(pitch), math.radians(yaw)
    return matrix_from_pose(Pose(x, y, z, roll, pitch, yaw))


def _matrix_from_quat(xyz: tuple[float, ...], q: tuple[float, ...]) -> Mat4:
    qx, qy, qz, qw = q
    n = math.sqrt(qx * qx + qy * qy + qz * qz + qw * qw) or 1.0
    qx, qy, qz, qw = qx / n, qy / n, qz / n, qw / n
    out = _EYE4.copy()
    out[:3, :3] = [
        [1 - 2 * (qy * qy + qz * qz), 2 * (qx * qy - qz * qw), 2 * (qx * qz + qy * qw)],
        [2 * (qx * qy + qz * qw), 1 - 2 * (qx * qx + qz * qz), 2 * (qy * qz - qx * qw)],
        [2 * (qx * qz - qy * qw), 2 * (qy * qz + qx * qw), 1 - 2 * (qx * qx + qy * qy)],
    ]
    out[:3, 3] = xyz
    return out
