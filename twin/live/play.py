"""Serve a recorded bag live: every decodable topic, at the bag's pace times `speed`, once or in a loop."""

from __future__ import annotations

import logging
import os
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from pathlib import Path

from twin.bag import message_definitions, open_bag, read_messages, robot_namespaces
from twin.bag.typesys import TypeRegistry, message_type_name
from twin.core.errors import BagError
from twin.live.namespace import NamespaceView
from twin.live.pacing import Pacer
from twin.live.server import LiveServer
from twin.live.sink import is_latched

__all__ = ["PlayReport", "play_bag"]

_log = logging.getLogger(__name__)


@dataclass(frozen=True, kw_only=True, slots=True)
class PlayReport:
    """What `play_bag` served."""

    bag_path: Path
    topics: tuple[str, ...]  #: the bag's topics served (under the names the bag has)
    skipped: tuple[str, ...]  #: topics left out: no message definition, so no client could decode them
    messages: int  #: messages published, over all passes
    passes: int  #: times the bag was played (more than one with `loop`)
    bag_s: float  #: bag time covered per pass
    stopped: bool  #: `should_stop` ended the playback
    reached_s: float = 0.0  #: bag time of the last message served (of the last pass), from the bag's start


def play_bag(
    path: str | os.PathLike[str],
    server: LiveServer,
    *,
    speed: float | None = 1.0,
    loop: bool = False,
    should_stop: Callable[[], bool] = lambda: False,
    on_pass: Callable[[int], None] | None = None,
    namespace: str | None = None,
    robots: Sequence[str] = (),
) -> PlayReport:
    """Publish the bag's messages on `server` in time order, paced to `speed` (None: as fast as possible).

    Args:
        path: A rosbag2 folder (MCAP or sqlite3, any metadata version the twin reads).
        server: Where to publish.
        speed: Bag seconds per wall second.
        loop: Play again from the start after the end, until `should_stop()`.
        should_stop: Polled before each message.
        on_pass: Called with the pass number (1, 2, ...) as each pass starts.
        namespace: A fleet's robot to serve alone: its topics without the namespace (`/robot1/scan` as
            `/scan`) and the topics under no namespace (`twin.live.namespace`); None: every topic as it is.
            In a bag whose robots share one `/tf` with prefixed frames (`robot1/odom`), its prefix
            is taken off its frames and the other robots' transforms are left out.
        robots: The bag's robots' namespaces (whose prefixed frames are not this robot's); empty: found in the bag.

    Raises:
        BagError: If the bag cannot be read, or has no topic with a message definition.
    """
    info = open_bag(path)
    definitions = message_definitions(info.path)
    handles: dict[str, int] = {}
    skipped = []
    view = None
    rewrites: dict[str, Callable[[bytes], bytes | None]] = {}
    registry = TypeRegistry()
    if namespace is not None:
        ns = namespace.strip("/")
        have = {t.name for t in info.topics}
        # The robots' TF on the one shared /tf, none under the namespace: frames named `robot1/odom`.
        shared = bool({"/tf", "/tf_static"} & have) and not {f"/{ns}/tf", f"/{ns}/tf_static"} & have
        if shared and not robots:
            robots = robot_namespaces(info)  # whose prefixed frames are not this robot's
        view = NamespaceView(ns, frame_prefix=shared, robots=robots)
    for topic in info.topics:
        served = view.served_as(topic.name) if view is not None else topic.name
        if served is None:
            continue  # another robot's
        definition = definitions.get(topic.msgtype)
        if definition is None:
            skipped.append(topic.name)
            _log.warning("%s: no definition of %s; %s is not served", info.path, topic.msgtype, topic.name)
            continue
        handles[topic.name] = server.add_channel(served, definition, latched=is_latched(topic.qos))
        if view is not None and view.frame_prefix:
            msgtype = message_type_name(topic.msgtype)
            if not registry.knows(msgtype):
                registry.register(msgtype, definition.text)
            rewrite = view.rewriter(msgtype, registry.store)
            if rewrite is not None:
                rewrites[topic.name] = rewrite
    if not handles:
        msg = f"{info.path}: no topic has a message definition (embedded or standard); nothing to serve"
        raise BagError(msg)
    server.ready()  # every channel is made: clients that came meanwhile go through now
    names = sorted(handles)
    pacer = Pacer(speed, should_stop=should_stop) if speed is not None else None
    publish = server.publish
    messages = passes = 0
    stopped = False
    while not stopped:
        passes += 1
        last_ns = info.start_ns
        if passes > 1:
            server.restart_time()
            if pacer is not None:
                pacer.restart()
        if on_pass is not None:
            on_pass(passes)
        sent = messages
        for m in read_messages(info.path, names, decode=False):
            if should_stop():
                stopped = True
                break
            if pacer is not None:
                pacer.wait(m.t_ns)
            data = m.msg
            if rewrites:
                rewrite = rewrites.get(m.topic)
                if rewrite is not None:
                    data = rewrite(bytes(data))
                    if data is None:
                        continue  # only other robots' transforms
            publish(handles[m.topic], m.t_ns, data)
            messages += 1
            last_ns = m.t_ns
        if not stopped and should_stop():  # (a pass may publish nothing: a stop is looked for after it too)
            stopped = True
        if not loop or messages == sent:  # a pass that published nothing would loop at full speed for ever
            break
    return PlayReport(
        bag_path=info.path,
        topics=tuple(names),
        skipped=tuple(skipped),
        messages=messages,
        passes=passes,
        bag_s=info.duration_ns / 1e9,
        stopped=stopped,
        reached_s=(last_ns - info.start_ns) / 1e9,
    )
