"""The run on a ROS 2 domain: its topics out over DDS with ROS 2's names and QoS, commands in.

`Ros2Bridge` is a sink of the executor (`twin.sim.executor.Sink`), after the recorder: every
publication it takes goes out as it was recorded, the same CDR bytes (encapsulation header
included, which is the RTPS serialized payload's header too) on the DDS topic `rt/<topic>` of type
`<pkg>::msg::dds_::<Name>_`, with the reliability, durability and depth the bag records for the
topic. Its `inbound_node` brings the topics external nodes publish (`ros2.subscribe`: `/cmd_vel`,
`/initialpose`) into the run: a node that takes what DDS received, every 10 ms of sim time, and
publishes it to the twin's subscribers and the bag like any other message.

Cyclone DDS (the `cyclonedds` binding, which carries its own C library) is imported only here, when
a run asks for ROS 2. By default it is told to use the loopback interface alone, with multicast off
and discovery by unicast to 127.0.0.1 (`cyclone_config`).
"""

from __future__ import annotations

import contextlib
import logging
import os
import sys
import tempfile
from collections.abc import Iterator, Mapping, Sequence
from typing import Any, Protocol
from xml.sax.saxutils import quoteattr

from twin.bag import Durability, QosProfile, Reliability, default_qos
from twin.core.errors import ConfigError
from twin.node import Node
from twin.ros2.dds_types import dds_topic_name, struct_type

__all__ = ["INBOUND_RATE_HZ", "BridgeSettings", "GraphTopic", "Ros2Bridge", "cyclone_config"]

_log = logging.getLogger(__name__)

#: How often (per sim second) the run takes what arrived from the domain: a command waits at most 10 ms.
INBOUND_RATE_HZ = 100.0
_TAKE_MAX = 64  # samples taken per topic per poll


@contextlib.contextmanager
def _c_stderr() -> Iterator[list[str]]:
    """Capture what C code writes to file descriptor 2 meanwhile: the list holds it once the block ends."""
    said: list[str] = []
    sys.stderr.flush()
    saved = os.dup(2)
    with tempfile.TemporaryFile() as sink:
        os.dup2(sink.fileno(), 2)
        try:
            yield said
        finally:
            os.dup2(saved, 2)
            os.close(saved)
            sink.seek(0)
            said.append(sink.read().decode("utf-8", "replace"))


class BridgeSettings(Protocol):
    """What the bridge needs of a scenario's `ros2:` section (`twin.sim.scenario.Ros2Section`)."""

    @property
    def domain_id(self) -> int:
        """The ROS 2 domain (ROS_DOMAIN_ID)."""
        ...

    @property
    def interface(self) -> str:
        """The network interface DDS uses (`lo`: loopback only)."""
        ...

    @property
    def publish(self) -> tuple[str, ...] | None:
        """The topics sent to the domain (None: every topic the run publishes)."""
        ...

    @property
    def subscribe(self) -> tuple[str, ...]:
        """The topics taken from the domain into the run."""
        ...


class GraphTopic(Protocol):
    """What the bridge needs of a topic of the run's graph (`twin.sim.executor.Topic`)."""

    msgtype: str
    publishers: list[str]


def cyclone_config(domain_id: int, interface: str = "lo") -> str:
    """The Cyclone DDS configuration a run hands to DDS.

    On `lo` (the default): the loopback interface alone, multicast off, participants found by
    unicast on 127.0.0.1, so nothing leaves the machine. Any other interface is used as Cyclone
    DDS would by default (multicast discovery on it).
    """
    general = f"<Interfaces><NetworkInterface name={quoteattr(interface)}/></Interfaces>"
    discovery = "<ParticipantIndex>auto</ParticipantIndex><MaxAutoParticipantIndex>32</MaxAutoParticipantIndex>"
    if interface == "lo":
        general += "<AllowMulticast>false</AllowMulticast>"
        # No multicast: participants on 127.0.0.1 are found by unicast announcements to each participant
        # index's port, every second, so a node started after the twin is found within one (default 30 s).
        discovery += '<Peers><Peer address="127.0.0.1"/></Peers><SPDPInterval>1s</SPDPInterval>'
    return (
        f'<CycloneDDS><Domain Id="{domain_id}"><General>{general}</General>'
        f"<Discovery>{discovery}</Discovery></Domain></CycloneDDS>"
    )


def _dds_qos(profile: QosProfile, *, inbound: bool = False) -> Any:
    """The Cyclone DDS QoS of a recorded ROS 2 QoS profile (history keep-last at its depth, 10 when unknown)."""
    from cyclonedds.core import Policy, Qos

    depth = profile.depth if profile.depth > 0 else 10
    reliability = (
        Policy.Reliability.BestEffort
        if profile.reliability == Reliability.BEST_EFFORT
        else Policy.Reliability.Reliable(max_blocking_time=100_000_000)
    )
    durability = (
        Policy.Durability.TransientLocal
        if profile.durability == Durability.TRANSIENT_LOCAL
        else Policy.Durability.Volatile
    )
    policies = [reliability, durability, Policy.History.KeepLast(depth)]
    if inbound:  # the run's own writer on a topic it also takes must not be heard
        policies.append(Policy.IgnoreLocal.Participant)
    return Qos(*policies)


class _Inbound(Node):
    """Publishes into the run what external nodes published on the domain's topics it takes."""

    builtin = True

    def __init__(self, bridge: Ros2Bridge, topics: Sequence[tuple[str, str, Any]]) -> None:
        super().__init__("ros2_bridge")
        from cyclonedds._clayer import ddspy_take
        from cyclonedds.core import InstanceState, SampleState, ViewState

        from twin.msgs import deserialize

        mask = SampleState.Any | ViewState.Any | InstanceState.Any
        bridge_ = bridge
        feeds = [(reader, self.create_publisher(msgtype, name, 10), msgtype) for name, msgtype, reader in topics]

        def take(_t_ns: int) -> None:
            for reader, pub, msgtype in feeds:
                got = ddspy_take(reader._ref, mask, _TAKE_MAX)
                if isinstance(got, int) or not got:
                    continue
                for data, info in got:
                    if not info.valid_data:
                        continue
                    msg = deserialize(data, msgtype)
                    bridge_.injecting = True  # not sent back out on the domain it came from
                    try:
                        pub.publish(msg)
                    finally:
                        bridge_.injecting = False

        self.create_rate_timer(INBOUND_RATE_HZ, take, priority=50)


class Ros2Bridge:
    """The run as a ROS 2 participant (see the module docstring). Use as a context manager.

    Args:
        section: The scenario's `ros2:` section (domain, role, topics out and in, interface).

    Raises:
        ConfigError: If the Cyclone DDS binding is missing or DDS cannot start (naming why).
    """

    def __init__(self, section: BridgeSettings) -> None:
        try:
            from cyclonedds.core import DDSException
            from cyclonedds.domain import Domain, DomainParticipant
        except ImportError as err:
            msg = f"--ros2 needs Cyclone DDS's Python binding ({err}); install it: pip install cyclonedds"
            raise ConfigError(msg) from None
        self.section = section
        self.injecting = False
        self._made: dict[str, Any] = {}
        self._topics: dict[str, Any] = {}
        self._writers: list[Any] = []
        self._readers: list[Any] = []
        self._in_only: set[str] = set()
        self.config = cyclone_config(section.domain_id, section.interface)
        with _c_stderr() as said:  # Cyclone writes its reasons to the C stderr: made part of our one line
            try:
                self._domain = Domain(section.domain_id, self.config)
                self._participant = DomainParticipant(section.domain_id)
                failure = None
            except DDSException as err:
                failure = str(err)
        # Cyclone's lines: a time stamp, the domain in brackets, the thread's name, the reason:
        # `1795769004.59 [0] twin: nosuch0: does not match an available interface.`
        lines = "".join(said).splitlines()
        said_now = [line.split("]", 1)[-1].strip().split(" ", 1)[-1].rstrip(".") for line in lines if line.strip()]
        reason = " ".join(said_now)
        if failure is not None:
            msg = (
                f"ros2: DDS cannot start on domain {section.domain_id}, interface {section.interface!r}: "
                f"{reason or failure}; check ros2.interface (ip link) and the domain id"
            )
            raise ConfigError(msg)
        if reason:
            _log.warning("ros2: Cyclone DDS: %s", reason)
        from cyclonedds._clayer import ddspy_write

        self._write = ddspy_write

    # -- the sink ----------------------------------------------------------------------------

    def add_topic(self, topic: str, msgtype: str, *, qos: Sequence[QosProfile] | None = None) -> Any:
        """Create the DDS writer of a topic the run publishes; None for a topic that stays in the run."""
        publish = self.section.publish
        if (publish is not None and topic not in publish) or topic in self._in_only:
            return None
        from cyclonedds.pub import DataWriter

        profile = (tuple(qos) if qos else default_qos(topic))[0]
        writer = DataWriter(self._participant, self._topic(topic, msgtype), _dds_qos(profile))
        self._writers.append(writer)
        return writer._ref

    def write(self, handle: Any, t_ns: int, data: bytes) -> None:
        """Send one recorded message as it is (padded to 4 bytes, as RTPS payloads are)."""
        if handle is None or self.injecting:
            return
        pad = -len(data) % 4
        self._write(handle, data + b"\0" * pad if pad else data)

    # -- what comes in ---------------------------------------------------------------------------

    def inbound_node(self, topics: Mapping[str, GraphTopic]) -> Node | None:
        """The node that brings `ros2.subscribe` into the run, typed by the run's graph (None: nothing to take).

        A topic no node of the run uses is skipped with a warning: its type is unknown.
        """
        from cyclonedds.sub import DataReader

        feeds = []
        for name in self.section.subscribe:
            known = topics.get(name)
            if known is None:
                _log.info("ros2.subscribe: no node of the run uses %s, so its type is unknown; not taken", name)
                continue
            if not known.publishers:
                self._in_only.add(name)
            profile = default_qos(name)[0]
            reader = DataReader(self._participant, self._topic(name, known.msgtype), _dds_qos(profile, inbound=True))
            self._readers.append(reader)
            feeds.append((name, known.msgtype, reader))
        return _Inbound(self, feeds) if feeds else None

    def _topic(self, name: str, msgtype: str) -> Any:
        from cyclonedds.topic import Topic as DdsTopic

        if name not in self._topics:
            from twin.msgs import typestore  # the store the run serialises with: it knows every type published

            store = typestore()
            if msgtype not in store.fielddefs:
                msg = f"ros2: {name}: the type {msgtype} has no definition to describe it on DDS"
                raise ConfigError(msg)
            dds_type = struct_type(msgtype, store, self._made)
            self._topics[name] = DdsTopic(self._participant, dds_topic_name(name), dds_type)
        return self._topics[name]

    # -- context manager -------------------------------------------------------------------------

    def close(self) -> None:
        """Leave the domain (idempotent): readers, writers and the participant are deleted."""
        self._readers.clear()
        self._writers.clear()
        self._topics.clear()
        self.__dict__.pop("_participant", None)
        self.__dict__.pop("_domain", None)

    def __enter__(self) -> Ros2Bridge:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()
