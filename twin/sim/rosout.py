"""`/rosout`: the twin's log lines and every node's, stamped with sim time, as rcl publishes them.

A node's logger (`twin.node.<name>`) logs under the node's name; the twin's own library lines log
as `twin`. The bridge is a node, so its lines reach the recorder like any other topic's; it encodes
them itself (`twin.bag.LogEncoder`), so a run that nobody reads `rcl_interfaces/Log` objects from
never builds them.

A bag carries nothing of the machine it was made on: lines about the machine (a kernel or FMU built
into the cache folder on a cold cache) stay on the console, and a line's source file is named
relative to the package it belongs to (`twin/sim/simulation.py`; a user's node file by its name),
never by its absolute path. A run on a cold cache and one on a warm cache record the same bytes.
"""

from __future__ import annotations

import logging
import os
from pathlib import Path

from twin.bag import LogEncoder
from twin.core.errors import TwinError
from twin.node import Encoded, Node

__all__ = ["MACHINE_LOGGERS", "RosoutBridge", "source_file"]

_LEVELS = ((logging.CRITICAL, 50), (logging.ERROR, 40), (logging.WARNING, 30), (logging.INFO, 20))
_NODE_PREFIX = "twin.node."

MACHINE_LOGGERS = ("twin.core.native", "twin.core.cache", "twin.cosim.build")
"""Loggers whose lines describe the machine (what was built into which cache folder), not the run."""

_PACKAGE_PARENT = str(Path(__file__).resolve().parent.parent.parent) + os.sep


def source_file(pathname: str) -> str:
    """The source file a log line names: relative to the twin package's folder, else the file's name alone."""
    if pathname.startswith(_PACKAGE_PARENT):
        return pathname[len(_PACKAGE_PARENT) :].replace(os.sep, "/")
    return os.path.basename(pathname)


class RosoutBridge(Node):
    """Publishes the log records of its `handler` (INFO and above) on `/rosout`; attach it while the run goes on."""

    builtin = True

    def __init__(self) -> None:
        super().__init__("rosout")
        self._pub = self.create_publisher(LogEncoder.msgtype, "/rosout", 1000)
        self._encoders: dict[str, LogEncoder] = {}
        self.handler = _Handler(self)

    def publish_record(self, record: logging.LogRecord) -> None:
        """Publish one log record."""
        level = next((ros for py, ros in _LEVELS if record.levelno >= py), 10)
        name = record.name[len(_NODE_PREFIX) :] if record.name.startswith(_NODE_PREFIX) else "twin"
        encoder = self._encoders.get(name)
        if encoder is None:
            encoder = self._encoders[name] = LogEncoder(name)
        text = record.getMessage()
        args = (self._graph_now(), level, text, (source_file(record.pathname), record.funcName, record.lineno))
        self._pub.publish(Encoded((encoder.encode_line, args, (level, name, text))))


class _Handler(logging.Handler):
    def __init__(self, bridge: RosoutBridge) -> None:
        super().__init__(level=logging.INFO)
        self._bridge = bridge

    def filter(self, record: logging.LogRecord) -> bool:
        name = record.name
        return not any(name == m or name.startswith(m + ".") for m in MACHINE_LOGGERS)

    def emit(self, record: logging.LogRecord) -> None:
        try:
            self._bridge.publish_record(record)
        except TwinError:
            self.handleError(record)
