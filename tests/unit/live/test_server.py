"""LiveServer and LiveSink in process: channels as foxglove_bridge advertises them, latched topics, binding."""

from __future__ import annotations

import asyncio
import socket
from pathlib import Path

import pytest

from tests.foxglove_client import watch
from twin.bag import QOS_LATCHED, QOS_RELIABLE, Recorder, StringEncoder, message_definitions, read_messages
from twin.bag.typesys import TypeRegistry
from twin.core.errors import ConfigError
from twin.live import LiveServer, LiveSink, is_latched

REGISTRY = TypeRegistry()


def test_a_channel_is_advertised_with_cdr_encoding_and_the_ros2msg_definition_the_recorder_embeds() -> None:
    definition = REGISTRY.definition("sensor_msgs/msg/LaserScan")
    with LiveServer(port=0) as server:
        server.add_channel("/scan", definition)
        seen = asyncio.run(watch(server.url, ["/scan"], stop=lambda w: "/scan" in w.channels, timeout_s=10))
    channel = seen.channels["/scan"]
    assert seen.subprotocol in ("foxglove.sdk.v1", "foxglove.websocket.v1")
    assert channel["encoding"] == "cdr"
    assert channel["schemaName"] == "sensor_msgs/msg/LaserScan"
    assert channel["schemaEncoding"] == "ros2msg"
    assert channel["schema"] == definition.text
    assert "time" in seen.server_info["capabilities"]


def test_a_client_that_connects_after_a_latched_message_still_receives_it() -> None:
    encoder = StringEncoder()
    with LiveServer(port=0) as server:
        latched = server.add_channel("/robot_description", REGISTRY.definition(encoder.msgtype), latched=True)
        volatile = server.add_channel("/chatter", REGISTRY.definition(encoder.msgtype))
        server.publish(latched, 0, encoder.encode("<robot name='tb3'/>"))
        server.publish(volatile, 0, encoder.encode("gone"))
        seen = asyncio.run(
            watch(
                server.url,
                ["/robot_description", "/chatter"],
                stop=lambda w: bool(w.messages["/robot_description"]),
                timeout_s=10,
            )
        )
    (t_ns, payload), *_ = seen.messages["/robot_description"]
    assert t_ns == 0
    assert seen.decode("/robot_description", payload).data == "<robot name='tb3'/>"
    assert seen.messages["/chatter"] == []  # volatile: a late client gets only what comes next


def _refused(host: str, port: int) -> bool:
    with socket.socket() as sock:
        sock.settimeout(2)
        return sock.connect_ex((host, port)) != 0


def test_the_server_binds_127_0_0_1_by_default_and_other_addresses_only_when_told() -> None:
    with LiveServer(port=0) as server:
        assert server.url == f"ws://127.0.0.1:{server.port}"
        assert not _refused("127.0.0.1", server.port)
        assert _refused("127.0.0.2", server.port)  # another loopback address: not bound
    with LiveServer(host="0.0.0.0", port=0) as server:
        assert not _refused("127.0.0.2", server.port)


def test_a_port_in_use_is_a_config_error_naming_the_address_and_the_fix() -> None:
    with socket.socket() as taken:
        taken.bind(("127.0.0.1", 0))
        taken.listen()
        port = taken.getsockname()[1]
        with pytest.raises(ConfigError) as err:
            LiveServer(port=port)
    text = str(err.value)
    assert f"127.0.0.1:{port}" in text and "in use" in text and "--port" in text
    assert "\n" not in text and err.value.exit_code == 2


def test_the_sink_advertises_each_topic_latched_as_its_qos_says_and_publishes_its_messages() -> None:
    encoder = StringEncoder()
    with LiveServer(port=0) as server:
        sink = LiveSink(server)
        a = sink.add_topic("/a", encoder.msgtype)
        b = sink.add_topic("/b", encoder.msgtype, qos=(QOS_LATCHED,))
        sink.write(a, 5, encoder.encode("volatile"))
        sink.write(b, 6, encoder.encode("latched"))
        seen = asyncio.run(watch(server.url, ["/a", "/b"], stop=lambda w: bool(w.messages["/b"]), timeout_s=10))
    assert seen.messages["/a"] == []
    assert [(t, seen.decode("/b", p).data) for t, p in seen.messages["/b"]] == [(6, "latched")]


def test_latched_means_every_offered_profile_is_transient_local() -> None:
    assert is_latched((QOS_LATCHED,))
    assert not is_latched((QOS_RELIABLE,))
    assert not is_latched((QOS_LATCHED, QOS_RELIABLE))
    assert not is_latched(())


def test_definitions_of_a_real_sqlite3_bag_come_from_the_type_store_and_undefined_types_are_left_out(
    fixtures: Path,
) -> None:
    bag = fixtures / "bags" / "tb3_waffle_gazebo_humble"
    definitions = message_definitions(bag)
    assert definitions["sensor_msgs/msg/LaserScan"].text == REGISTRY.definition("sensor_msgs/msg/LaserScan").text
    assert "gazebo_msgs/msg/PerformanceMetrics" not in definitions


def test_definitions_of_the_twins_bag_are_the_ones_it_embedded(tmp_path: Path) -> None:
    with Recorder(tmp_path / "bag") as rec:
        handle = rec.add_topic("/robot_description", StringEncoder.msgtype)
        rec.write(handle, 0, StringEncoder().encode("<robot/>"))
    definitions = message_definitions(tmp_path / "bag")
    assert definitions == {"std_msgs/msg/String": REGISTRY.definition("std_msgs/msg/String")}
    assert [m.msg.data for m in read_messages(tmp_path / "bag")] == ["<robot/>"]


def test_a_client_on_the_older_foxglove_websocket_v1_subprotocol_connects_and_receives(
    monkeypatch: pytest.MonkeyPatch,
) -> None:
    # foxglove-sdk's own server answers this client HTTP 400; the front renames the subprotocol for it.
    import tests.foxglove_client

    monkeypatch.setattr(tests.foxglove_client, "SUBPROTOCOLS", ["foxglove.websocket.v1"])
    encoder = StringEncoder()
    with LiveServer(port=0) as server:
        latched = server.add_channel("/robot_description", REGISTRY.definition(encoder.msgtype), latched=True)
        server.publish(latched, 7, encoder.encode("<robot name='tb3'/>"))
        seen = asyncio.run(
            watch(
                server.url, ["/robot_description"], stop=lambda w: bool(w.messages["/robot_description"]), timeout_s=10
            )
        )
    assert seen.subprotocol == "foxglove.websocket.v1"
    assert [(t, seen.decode("/robot_description", p).data) for t, p in seen.messages["/robot_description"]] == [
        (7, "<robot name='tb3'/>")
    ]


def test_a_client_on_an_unknown_subprotocol_is_refused_with_one_log_line(caplog: pytest.LogCaptureFixture) -> None:
    import websockets

    async def attempts(url: str) -> list[int]:
        codes = []
        for _ in range(5):  # a client retries, as Foxglove does
            with pytest.raises(websockets.InvalidStatus) as err:
                await websockets.connect(url, subprotocols=["foxglove.websocket.v2"], proxy=None)  # type: ignore[list-item]
            codes.append(err.value.response.status_code)
        return codes

    with caplog.at_level("WARNING"), LiveServer(port=0) as server:
        assert asyncio.run(attempts(server.url)) == [400] * 5
    lines = [r.getMessage() for r in caplog.records if r.levelname in ("WARNING", "ERROR")]
    assert len(lines) == 1, lines
    assert "foxglove.websocket.v2" in lines[0] and "foxglove.sdk.v1" in lines[0] and "foxglove.websocket.v1" in lines[0]
    assert "handshake failed" not in " ".join(r.getMessage() for r in caplog.records)


def _handshake(port: int) -> socket.socket:
    """A raw WebSocket opening handshake to the server, as a Foxglove client sends it."""
    sock = socket.create_connection(("127.0.0.1", port), timeout=10)
    sock.sendall(
        b"GET / HTTP/1.1\r\nHost: 127.0.0.1\r\nUpgrade: websocket\r\nConnection: Upgrade\r\n"
        b"Sec-WebSocket-Key: dGhlIHNhbXBsZSBub25jZQ==\r\nSec-WebSocket-Version: 13\r\n"
        b"Sec-WebSocket-Protocol: foxglove.websocket.v1\r\n\r\n"
    )
    return sock


def test_a_run_holds_its_clients_until_every_channel_is_made() -> None:
    # A client that came while a run made its channels could subscribe to one the SDK did not accept
    # yet ("Unknown channel ID"), and Foxglove never asks again: no /tf_static all session.
    definition = REGISTRY.definition("sensor_msgs/msg/LaserScan")
    with LiveServer(port=0, hold_clients=True) as server:
        sock = _handshake(server.port)
        server.add_channel("/scan", definition)
        sock.settimeout(0.3)
        with pytest.raises(TimeoutError):  # held: no answer before the server is ready (load only delays it more)
            sock.recv(1)
        server.ready()
        sock.settimeout(10)
        assert sock.recv(64).startswith(b"HTTP/1.1 101")
        sock.close()
        seen = asyncio.run(watch(server.url, ["/scan"], stop=lambda w: "/scan" in w.channels, timeout_s=10))
    assert "/scan" in seen.channels


def test_closing_the_server_sends_its_clients_a_close_frame() -> None:
    # The front was closed before the SDK's server: clients saw the connection drop (1006) instead
    from websockets.asyncio.client import connect
    from websockets.exceptions import ConnectionClosedOK

    async def until_closed(server: LiveServer) -> None:
        async with connect(server.url, subprotocols=["foxglove.websocket.v1"], open_timeout=10) as ws:  # type: ignore[list-item]
            await ws.recv()  # serverInfo
            await asyncio.get_running_loop().run_in_executor(None, server.close)
            with pytest.raises(ConnectionClosedOK):
                while True:
                    await asyncio.wait_for(ws.recv(), timeout=10)

    with LiveServer(port=0) as server:
        server.add_channel("/scan", REGISTRY.definition("sensor_msgs/msg/LaserScan"))
        asyncio.run(until_closed(server))
