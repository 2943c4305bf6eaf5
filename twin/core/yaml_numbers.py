"""The one YAML loader twin reads with: PyYAML's safe loader, with numbers as people write them.

PyYAML resolves plain scalars by YAML 1.1 rules, where `1e12`, `1.0e6` and `2e+3` are strings (a
float needs a dot and a signed exponent). YAML 1.2, and every user, reads them as numbers.
`Loader` adds that float form; `safe_load(text)` is `yaml.safe_load` with it. Every YAML file
twin reads (scenarios, mappings, locations, params, bag metadata) goes through this loader.
"""

from __future__ import annotations

import re
from typing import Any

import yaml

__all__ = ["Loader", "safe_load"]

_FLOAT_12 = re.compile(
    r"""^(?:[-+]?(?:[0-9][0-9_]*)(?:\.[0-9_]*)?[eE][-+]?[0-9]+
    |[-+]?\.[0-9_]+[eE][-+]?[0-9]+)$""",
    re.VERBOSE,
)


class Loader(yaml.SafeLoader):
    """`yaml.SafeLoader` that also reads YAML 1.2 floats such as `1e12`, `1.0e6`, `2e+3`."""


Loader.add_implicit_resolver("tag:yaml.org,2002:float", _FLOAT_12, list("-+0123456789."))


def safe_load(text: str) -> Any:
    """Parse one YAML document with `Loader` (plain data only, as `yaml.safe_load`)."""
    return yaml.load(text, Loader=Loader)  # Loader is a SafeLoader
