"""The one YAML loader twin reads with: PyYAML's safe loader, with numbers as people write them.

PyYAML resolves plain scalars by YAML 1.1 rules, where `1e12`, `1.0e6` and `2e+3` are strings (a
float needs a dot and a signed exponent). YAML 1.2, and every user, reads them as numbers.
`Loader` adds that float form; `safe_load(text)` is `yaml.safe_load` with it. Every YAML file
twin reads (scenarios, mappings, locations, params, bag metadata) goes through this loader.

Parsing runs in libyaml (PyYAML's C parser, ten times faster: a scenario with its defaults is read
in a millisecond instead of ten) with the same resolvers and constructors, so the values and nodes
are the same. A document libyaml refuses is read again by the pure-Python parser, which words the
error as before and reads what libyaml alone refuses (flow nesting past 1,000 levels).
"""

from __future__ import annotations

import io
import re
from typing import Any

import yaml

__all__ = ["Loader", "compose", "safe_load"]

_FLOAT_12 = re.compile(
    r"""^(?:[-+]?(?:[0-9][0-9_]*)(?:\.[0-9_]*)?[eE][-+]?[0-9]+
    |[-+]?\.[0-9_]+[eE][-+]?[0-9]+)$""",
    re.VERBOSE,
)


class Loader(yaml.SafeLoader):
    """`yaml.SafeLoader` that also reads YAML 1.2 floats such as `1e12`, `1.0e6`, `2e+3`."""


Loader.add_implicit_resolver("tag:yaml.org,2002:float", _FLOAT_12, list("-+0123456789."))

_CLoader: type[yaml.CSafeLoader] | None = None
if getattr(yaml, "__with_libyaml__", False):

    class _CLoaderType(yaml.CSafeLoader):
        """`Loader` on libyaml's parser."""

    _CLoaderType.add_implicit_resolver("tag:yaml.org,2002:float", _FLOAT_12, list("-+0123456789."))
    _CLoader = _CLoaderType


class _NamedText(io.StringIO):
    """Text that libyaml's parser names its marks after (it takes the name of a stream, not of a str)."""

    def __init__(self, text: str, name: str) -> None:
        super().__init__(text)
        self.name = name


def safe_load(text: str) -> Any:
    """Parse one YAML document with `Loader` (plain data only, as `yaml.safe_load`).

    Raises:
        yaml.YAMLError: As `yaml.safe_load` with `Loader` raises it.
    """
    if _CLoader is not None:
        loader = _CLoader(text)
        try:
            return loader.get_single_data()
        except yaml.YAMLError:
            pass  # read again below, for the pure-Python parser's words (or its deeper nesting)
        finally:
            loader.dispose()
    return yaml.load(text, Loader=Loader)  # Loader is a SafeLoader


def compose(text: str, name: str) -> yaml.Node | None:
    """Parse one YAML document into its node tree, marks naming `name`; None for an empty document.

    Raises:
        yaml.YAMLError: As `Loader(text).get_single_node()` raises it.
        RecursionError: If the document nests deeper than the pure-Python parser can follow.
    """
    if _CLoader is not None:
        loader = _CLoader(_NamedText(text, name))
        try:
            node: yaml.Node | None = loader.get_single_node()
            return node
        except yaml.YAMLError:
            pass  # read again below, for the pure-Python parser's words (or its deeper nesting)
        finally:
            loader.dispose()
    python = Loader(text)
    python.name = name
    try:
        fallback: yaml.Node | None = python.get_single_node()
        return fallback
    finally:
        python.dispose()
