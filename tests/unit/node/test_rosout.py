"""`/rosout`: log lines reach the recorder and subscribers, with the fast encoder as with rosbags' serialiser."""

from __future__ import annotations

import logging
from typing import Any

import pytest

from tests.unit.sim.test_executor import FakeSink
from twin.bag import LogEncoder
from twin.msgs import serialize
from twin.node import Node
from twin.node.rosout import RosoutBridge
from twin.sim.executor import Executor


def _encode(stamp_ns: int, level: int, name: str, message: str, file: str, function: str, line: int) -> bytes:
    return LogEncoder(name).encode(stamp_ns, level, message, file=file, function=function, line=line)


class LogListener(Node):
    def __init__(self) -> None:
        super().__init__("listener")
        self.heard: list[Any] = []
        self.create_subscription("rcl_interfaces/msg/Log", "/rosout", self.heard.append, 10)


@pytest.mark.parametrize("encode", [None, _encode], ids=["rosbags", "encoder"])
def test_a_log_line_is_recorded_as_rosbags_serialises_it_and_heard_as_a_log_message(encode: Any) -> None:
    sink = FakeSink()
    executor = Executor(1_000_000)
    executor.add_sink(sink)
    bridge = RosoutBridge(encode)
    listener = LogListener()
    executor.add_node(bridge)
    executor.add_node(listener)
    executor.now_ns = 2_500_000_000
    logger = logging.getLogger("twin.node.amcl")
    logger.addHandler(bridge.handler)
    try:
        logger.warning("Setting pose %.3f", 1.25)
    finally:
        logger.removeHandler(bridge.handler)
    (msg,) = listener.heard
    assert (msg.stamp.sec, msg.stamp.nanosec) == (2, 500_000_000)
    assert (msg.level, msg.name, msg.msg) == (30, "amcl", "Setting pose 1.250")
    assert msg.file.endswith("test_rosout.py") and msg.function.startswith("test_a_log_line")
    ((topic, t_ns, data),) = [w for w in sink.writes if w[0] == "/rosout"]
    assert (topic, t_ns) == ("/rosout", 2_500_000_000)
    assert data == serialize(msg, "rcl_interfaces/msg/Log")
