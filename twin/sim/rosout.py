"""`/rosout`: the twin's log lines and every node's, stamped with sim time, as rcl publishes them.

A node's logger (`twin.node.<name>`) logs under the node's name; the twin's own library lines log
as `twin`. The bridge is a node, so its lines reach the recorder like any other topic's; it encodes
them itself (`twin.bag.LogEncoder`), so a run that nobody reads `rcl_interfaces/Log` objects from
never builds them.
"""

from __future__ import annotations

import logging

from twin.bag import LogEncoder
from twin.core.errors import TwinError
from twin.node import Encoded, Node

__all__ = ["RosoutBridge"]

_LEVELS = ((logging.CRITICAL, 50), (logging.ERROR, 40), (logging.WARNING, 30), (logging.INFO, 20))
_NODE_PREFIX = "twin.node."


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
        args = (self._graph_now(), level, text, (record.pathname, record.funcName, record.lineno))
        self._pub.publish(Encoded((encoder.encode_line, args, (level, name, text))))


class _Handler(logging.Handler):
    def __init__(self, bridge: RosoutBridge) -> None:
        super().__init__(level=logging.INFO)
        self._bridge = bridge

    def emit(self, record: logging.LogRecord) -> None:
        try:
            self._bridge.publish_record(record)
        except TwinError:
            self.handleError(record)
