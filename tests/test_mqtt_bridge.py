"""MqttBridge against a real mosquitto: topics, retain flags, commands, will, restarts."""

from __future__ import annotations

import asyncio
import json
import os
import signal
import sys
import time
from collections.abc import AsyncIterator
from pathlib import Path

import aiomqtt
import pytest

from ptzd.mqtt.bridge import MqttBridge, optional_bridge
from ptzd.mqtt.config import MqttConfig, mqtt_config_from_url
from ptzd.mqtt.messages import (
    GotoPreset,
    Move,
    MoveDirection,
    SelectTarget,
    SetAutotrack,
    Stop,
    TrackMessage,
    TrackState,
    ZoomDirection,
    ZoomMove,
)
from tests.mqtt_helpers import Broker, Received, free_port, make_tls_files, publish, subscriber

REPO = Path(__file__).resolve().parents[1]
CAM = "cam1"
T = f"ptzd/{CAM}"


def fast_config(url: str, **overrides: object) -> MqttConfig:
    return mqtt_config_from_url(url, reconnect_min_s=0.05, reconnect_max_s=0.3, **overrides)


def track(i: float, state: TrackState = TrackState.TRACKING) -> TrackMessage:
    return TrackMessage(
        ts=1_700_000_000.0 + i,
        state=state,
        frame_size=(640, 480),
        id=7,
        bbox=(100.0 + i, 50.0, 64.0, 128.0),
        confidence=0.9,
        velocity=(12.5, -3.0),
    )


@pytest.fixture
async def broker(tmp_path: Path) -> AsyncIterator[Broker]:
    b = Broker(tmp_path)
    b.start()
    try:
        yield b
    finally:
        b.stop()


async def connected_bridge(bridge: MqttBridge) -> MqttBridge:
    await asyncio.wait_for(bridge.wait_connected(), 10)
    return bridge


async def retained_snapshot(port: int, topics: list[str]) -> dict[str, Received]:
    """What a fresh subscriber is handed on connect: the retained messages only."""
    async with subscriber(port, f"{T}/#") as rec:
        for topic in topics:
            await rec.wait_for(topic)
    return {m.topic: m for m in rec.messages if m.retain}


async def test_availability_online_retained_offline_on_clean_shutdown(broker: Broker) -> None:
    async with subscriber(broker.port, f"{T}/#") as live:
        async with MqttBridge(fast_config(broker.url), CAM) as bridge:
            await connected_bridge(bridge)
            snap = await retained_snapshot(broker.port, [f"{T}/availability"])
            assert snap[f"{T}/availability"].payload == b"online"
            assert snap[f"{T}/availability"].qos == 1
            await live.wait_for(f"{T}/availability")
            start = len(live.messages)
        # leaving the context published `offline` itself, before disconnecting
        got = await live.wait_for(f"{T}/availability", start=start)
        assert got.payload == b"offline"
    snap = await retained_snapshot(broker.port, [f"{T}/availability"])
    assert snap[f"{T}/availability"].payload == b"offline"


async def test_retained_state_on_change_and_ptz_state(broker: Broker) -> None:
    async with (
        subscriber(broker.port, f"{T}/#") as live,
        MqttBridge(fast_config(broker.url), CAM) as bridge,
    ):
        await connected_bridge(bridge)
        bridge.set_zoom_layer(2)
        bridge.set_autotrack(True)
        bridge.set_ptz_state(pan=-20, tilt=5, zoom=1)
        await live.wait_for(f"{T}/zoom_layer")
        await live.wait_for(f"{T}/autotrack/state")
        ptz = await live.wait_for(f"{T}/ptz/state")
        assert json.loads(ptz.payload) == {"pan": -20, "tilt": 5, "zoom": "in", "source": "auto"}
        # unchanged values are not re-sent; changed ones are
        bridge.set_zoom_layer(2)
        bridge.set_autotrack(True)
        bridge.set_ptz_state(pan=-20, tilt=5, zoom=1)
        bridge.set_zoom_layer(3)
        bridge.set_ptz_state(pan=0, tilt=0, zoom=0, source="manual")
        await live.wait_for(f"{T}/zoom_layer", lambda m: m.payload == b"3")
        await live.wait_for(f"{T}/ptz/state", lambda m: b'"pan":0' in m.payload)
        assert [m.payload for m in live.on(f"{T}/zoom_layer")] == [b"2", b"3"]
        assert [m.payload for m in live.on(f"{T}/autotrack/state")] == [b"ON"]
        assert len(live.on(f"{T}/ptz/state")) == 2
        snap = await retained_snapshot(broker.port, [f"{T}/zoom_layer", f"{T}/autotrack/state"])
        assert snap[f"{T}/zoom_layer"].payload == b"3"
        assert snap[f"{T}/autotrack/state"].payload == b"ON"
        assert f"{T}/ptz/state" not in snap  # not retained
        assert f"{T}/track" not in snap


async def test_track_payload_and_rate_coalescing(broker: Broker) -> None:
    rate = 10.0
    async with (
        subscriber(broker.port, f"{T}/track") as live,
        MqttBridge(fast_config(broker.url, track_rate_hz=rate), CAM) as bridge,
    ):
        await connected_bridge(bridge)
        duration = 1.5
        start = time.monotonic()
        sent = 0
        while time.monotonic() - start < duration:  # a 200 Hz producer
            bridge.publish_track(track(sent))
            sent += 1
            await asyncio.sleep(0.005)
        last = track(sent - 1)
        await live.wait_for(f"{T}/track", lambda m: json.loads(m.payload)["ts"] == last.ts)
        got = live.on(f"{T}/track")
        # at most rate * duration (+1 for the first, +1 for the trailing newest)
        assert len(got) <= rate * duration + 2, len(got)
        assert len(got) >= rate * duration * 0.6, len(got)
        assert bridge.stats.tracks_coalesced >= sent - len(got) - 1
        assert all(not m.retain and m.qos == 0 for m in got)
        body = json.loads(got[-1].payload)
        assert set(body) == {
            "ts", "state", "id", "bbox", "bbox_norm", "confidence", "velocity", "frame_size",
            "tracker",
        }  # fmt: skip
        assert body["state"] == "tracking"
        assert body["bbox"] == [100.0 + sent - 1, 50.0, 64.0, 128.0]
        assert body["bbox_norm"] == pytest.approx(
            [(100.0 + sent - 1) / 640, 50 / 480, 64 / 640, 128 / 480], abs=1e-4
        )
        assert body["frame_size"] == [640, 480]
        assert body["velocity"] == [12.5, -3.0]
        # gaps between messages respect the rate (allow scheduling jitter)
        bridge.publish_track(TrackMessage(ts=1.0, state=TrackState.LOST, frame_size=(640, 480)))
        lost = await live.wait_for(f"{T}/track", lambda m: json.loads(m.payload)["state"] == "lost")
        assert json.loads(lost.payload)["bbox"] is None
        assert json.loads(lost.payload)["bbox_norm"] is None


async def test_acquisition_transitions_survive_coalescing(broker: Broker) -> None:
    async with (
        subscriber(broker.port, f"{T}/track") as live,
        MqttBridge(fast_config(broker.url, track_rate_hz=2.0), CAM) as bridge,
    ):
        await connected_bridge(bridge)
        first = track(0)
        bridge.publish_track(first)  # sent at once; the next ones wait for the rate
        await live.wait_for(f"{T}/track", lambda m: json.loads(m.payload)["ts"] == first.ts)
        size = (640, 480)
        lock = {"t": 1.0, "from": "searching", "state": "tracking", "reason": "acquired",
                "bbox": [1.0, 2.0, 3.0, 4.0]}  # fmt: skip
        hide = {**lock, "t": 1.1, "from": "tracking", "state": "occluded", "reason": "occluded"}
        bridge.publish_track(TrackMessage(ts=1.0, state="tracking", frame_size=size,
                                          transitions=(lock,)))  # fmt: skip
        bridge.publish_track(TrackMessage(ts=1.1, state="occluded", frame_size=size,
                                          transitions=(hide,)))  # fmt: skip
        bridge.publish_track(TrackMessage(ts=1.2, state="occluded", frame_size=size))
        last = await live.wait_for(f"{T}/track", lambda m: json.loads(m.payload)["ts"] == 1.2)
        body = json.loads(last.payload)
        # the two middle messages were coalesced away, their transitions were not
        assert [m for m in live.on(f"{T}/track") if json.loads(m.payload)["ts"] in (1.0, 1.1)] == []
        assert body["transitions"] == [lock, hide]
        assert "transitions" not in json.loads(live.on(f"{T}/track")[0].payload)


async def _next_command(bridge: MqttBridge) -> object:
    async with asyncio.timeout(5):
        async for command in bridge.commands():
            return command
    raise AssertionError("command stream ended")


async def test_each_command_is_delivered_typed(broker: Broker) -> None:
    async with (
        subscriber(broker.port, f"{T}/#") as live,
        MqttBridge(fast_config(broker.url), CAM) as bridge,
    ):
        await connected_bridge(bridge)
        cases: list[tuple[str, bytes, object]] = [
            ("autotrack/set", b"ON", SetAutotrack(True)),
            ("autotrack/set", b"off", SetAutotrack(False)),
            ("autotrack/set", b" On\n", SetAutotrack(True)),
            ("ptz", b"preset_3", GotoPreset(3)),
            ("ptz", b"MOVE_LEFT", Move(MoveDirection.LEFT)),
            ("ptz", b"MOVE_RIGHT", Move(MoveDirection.RIGHT)),
            ("ptz", b"MOVE_UP", Move(MoveDirection.UP)),
            ("ptz", b"move_down", Move(MoveDirection.DOWN)),
            ("ptz", b"ZOOM_IN", ZoomMove(ZoomDirection.IN)),
            ("ptz", b"ZOOM_OUT", ZoomMove(ZoomDirection.OUT)),
            ("ptz", b"STOP", Stop()),
            ("ptz", b'{"select": [10, 20.5, 30, 40]}', SelectTarget((10.0, 20.5, 30.0, 40.0))),
        ]
        for suffix, payload, expected in cases:
            await publish(broker.port, f"{T}/{suffix}", payload)
            assert await _next_command(bridge) == expected, payload
        # autotrack/set is acknowledged on the retained state topic
        states = [m.payload for m in live.on(f"{T}/autotrack/state")]
        assert states[-1] == b"ON" and b"OFF" in states
        assert bridge.stats.commands_accepted == len(cases)
        assert not live.on(f"{T}/error")


BAD_PAYLOADS: list[tuple[str, bytes, str]] = [
    ("ptz", b"MOVE_SIDEWAYS", "unknown command"),
    ("ptz", b"preset_0", "outside 1..255"),
    ("ptz", b"preset_999", "outside 1..255"),
    ("ptz", b"preset_x", "unknown command"),
    ("ptz", b"", "empty payload"),
    ("ptz", b"\x00\xff\xfe\x80binary", "not UTF-8"),
    ("ptz", b"STOP\x00", "control characters"),
    ("ptz", b"X" * 5000, "too large"),
    ("ptz", b'{"select": [1, 2, 3]}', "four numbers"),
    ("ptz", b'{"select": [1, 2, 0, 4]}', "> 0"),
    ("ptz", b'{"select": [1, 2, NaN, 4]}', "finite"),
    ("ptz", b'{"select": [1, 2, 1e400, 4]}', "finite"),
    ("ptz", b'{"select": [1, 2, 3, 4], "x": 1}', 'optional "ts"'),
    ("ptz", b'{"select": [1, 2, 3, 4]', "malformed JSON"),
    ("ptz", b'{"select": [true, 2, 3, 4]}', "four numbers"),
    ("autotrack/set", b"maybe", "expected ON or OFF"),
    ("autotrack/set", b"\xc3\x28", "not UTF-8"),
    ("autotrack/set", b"O" * 2000, "too large"),
]


async def test_garbage_binary_and_oversized_payloads_are_rejected(broker: Broker) -> None:
    async with (
        subscriber(broker.port, f"{T}/error") as errors,
        MqttBridge(fast_config(broker.url), CAM) as bridge,
    ):
        await connected_bridge(bridge)
        for i, (suffix, payload, reason) in enumerate(BAD_PAYLOADS):
            await publish(broker.port, f"{T}/{suffix}", payload)
            got = await errors.wait_for(f"{T}/error", start=i)
            body = json.loads(got.payload)
            assert reason in body["error"], (payload[:40], body)
            assert body["topic"] == f"{T}/{suffix}"
            assert not got.retain and got.qos == 0
            assert body["payload_bytes"] == len(payload)
            assert len(body["payload_preview"]) <= 67  # never echoes a large payload
        assert bridge.stats.commands_rejected == len(BAD_PAYLOADS)
        assert bridge.stats.commands_accepted == 0
        # still alive and serving after all that
        await publish(broker.port, f"{T}/ptz", b"STOP")
        assert await _next_command(bridge) == Stop()


async def test_retained_ptz_command_is_ignored_on_connect(broker: Broker) -> None:
    await publish(broker.port, f"{T}/ptz", b"MOVE_LEFT", retain=True)
    async with (
        subscriber(broker.port, f"{T}/error") as errors,
        MqttBridge(fast_config(broker.url), CAM) as bridge,
    ):
        await connected_bridge(bridge)
        got = await errors.wait_for(f"{T}/error")
        assert "retained" in json.loads(got.payload)["error"]
        await publish(broker.port, f"{T}/ptz", b"STOP")
        assert await _next_command(bridge) == Stop()  # MOVE_LEFT was never delivered


async def test_command_queue_drops_oldest_when_daemon_lags(broker: Broker) -> None:
    cfg = fast_config(broker.url, command_queue_size=2)
    async with MqttBridge(cfg, CAM) as bridge:
        await connected_bridge(bridge)
        for word in (b"MOVE_LEFT", b"MOVE_UP", b"ZOOM_IN", b"STOP"):
            await publish(broker.port, f"{T}/ptz", word)
        async with asyncio.timeout(5):
            # the counter is the observable here; there is no event to wait on
            while bridge.stats.commands_accepted < 4:  # noqa: ASYNC110
                await asyncio.sleep(0.01)
        assert bridge.stats.commands_dropped == 2
        assert await _next_command(bridge) == ZoomMove(ZoomDirection.IN)
        assert await _next_command(bridge) == Stop()


async def test_broker_down_drops_and_counts_then_republishes(tmp_path: Path) -> None:
    port = free_port()
    broker = Broker(tmp_path, port=port)
    async with MqttBridge(fast_config(broker.url), CAM) as bridge:
        # no broker yet: nothing blocks, tracks are dropped and counted, state is kept
        before = time.monotonic()
        for i in range(100):
            bridge.publish_track(track(i))
        bridge.set_zoom_layer(4)
        bridge.set_autotrack(False)
        assert time.monotonic() - before < 0.05
        assert bridge.stats.dropped_disconnected == 100
        await asyncio.sleep(0.5)
        assert not bridge.connected
        assert bridge.stats.connect_failures >= 2  # it keeps retrying with backoff
        broker.start()
        try:
            await connected_bridge(bridge)
            snap = await retained_snapshot(
                port, [f"{T}/availability", f"{T}/zoom_layer", f"{T}/autotrack/state"]
            )
            assert snap[f"{T}/availability"].payload == b"online"
            assert snap[f"{T}/zoom_layer"].payload == b"4"
            assert snap[f"{T}/autotrack/state"].payload == b"OFF"

            # broker restart mid-run (persistence off: it forgets every retained message)
            broker.stop()
            await asyncio.sleep(0.2)
            assert not bridge.connected
            bridge.set_zoom_layer(5)  # changes while down are not lost
            bridge.publish_track(track(1))
            broker.start()
            await connected_bridge(bridge)
            snap = await retained_snapshot(
                port, [f"{T}/availability", f"{T}/zoom_layer", f"{T}/autotrack/state"]
            )
            assert snap[f"{T}/availability"].payload == b"online"
            assert snap[f"{T}/zoom_layer"].payload == b"5"
            assert snap[f"{T}/autotrack/state"].payload == b"OFF"
            assert bridge.stats.connects == 2
            # and it works as before
            async with subscriber(port, f"{T}/track") as live:
                bridge.publish_track(track(2))
                await live.wait_for(f"{T}/track")
        finally:
            broker.stop()


CHILD = """
import asyncio, sys
from ptzd.mqtt.bridge import MqttBridge
from ptzd.mqtt.config import mqtt_config_from_url

async def main():
    async with MqttBridge(mqtt_config_from_url(sys.argv[1]), sys.argv[2]) as bridge:
        await bridge.wait_connected()
        bridge.set_autotrack(True)
        print("connected", flush=True)
        await asyncio.Event().wait()

asyncio.run(main())
"""


async def test_will_is_offline_retained_after_kill_9(broker: Broker) -> None:
    async with subscriber(broker.port, f"{T}/availability") as live:
        child = await asyncio.create_subprocess_exec(
            sys.executable,
            "-c",
            CHILD,
            broker.url,
            CAM,
            stdout=asyncio.subprocess.PIPE,
            stderr=asyncio.subprocess.DEVNULL,
            env={**os.environ, "PYTHONPATH": str(REPO)},
        )
        try:
            assert child.stdout is not None
            async with asyncio.timeout(20):
                while (line := await child.stdout.readline()) and line.strip() != b"connected":
                    pass  # the child's own log lines
            assert line.strip() == b"connected"
            await live.wait_for(f"{T}/availability", lambda m: m.payload == b"online")
            child.send_signal(signal.SIGKILL)
            await asyncio.wait_for(child.wait(), 10)
            got = await live.wait_for(f"{T}/availability", lambda m: m.payload == b"offline")
            assert got.qos == 1
        finally:
            if child.returncode is None:
                child.kill()
                await child.wait()
    snap = await retained_snapshot(broker.port, [f"{T}/availability"])
    assert snap[f"{T}/availability"].payload == b"offline"


async def test_home_assistant_discovery(broker: Broker) -> None:
    cfg = fast_config(broker.url, discovery=True)
    async with (
        subscriber(broker.port, "homeassistant/#") as live,
        MqttBridge(cfg, CAM) as bridge,
    ):
        await connected_bridge(bridge)
        switch = await live.wait_for("homeassistant/switch/ptzd_cam1/autotrack/config")
        state = await live.wait_for("homeassistant/sensor/ptzd_cam1/state/config")
        zoom = await live.wait_for("homeassistant/sensor/ptzd_cam1/zoom_layer/config")
        for m in (switch, state, zoom):
            assert m.qos == 1
            body = json.loads(m.payload)
            assert body["availability_topic"] == f"{T}/availability"
            assert body["device"]["identifiers"] == ["ptzd_cam1"]
        assert json.loads(switch.payload)["command_topic"] == f"{T}/autotrack/set"
        assert json.loads(switch.payload)["state_topic"] == f"{T}/autotrack/state"
        assert json.loads(state.payload)["state_topic"] == f"{T}/track"
        assert json.loads(zoom.payload)["state_topic"] == f"{T}/zoom_layer"
    snap = await retained_snapshot(broker.port, [])
    assert snap == {} or all(m.topic.startswith(T) for m in snap.values())
    async with subscriber(broker.port, "homeassistant/#") as late:
        got = await late.wait_for("homeassistant/switch/ptzd_cam1/autotrack/config")
        assert got.retain


async def test_discovery_off_by_default(broker: Broker) -> None:
    async with (
        subscriber(broker.port, "#") as live,
        MqttBridge(fast_config(broker.url), CAM) as bridge,
    ):
        await connected_bridge(bridge)
        await live.wait_for(f"{T}/availability")
    assert not [m for m in live.messages if m.topic.startswith("homeassistant/")]


async def test_username_password_from_systemd_credential(tmp_path: Path) -> None:
    broker = Broker(tmp_path, passwords={"ptzd": "s3cret pass"})
    broker.start()
    try:
        creds = tmp_path / "creds"
        creds.mkdir()
        (creds / "mqtt-password").write_text("s3cret pass\n")
        cfg = fast_config(broker.url, username="ptzd")
        env = {"CREDENTIALS_DIRECTORY": str(creds)}
        async with MqttBridge(cfg, CAM, environ=env) as bridge:
            await connected_bridge(bridge)
            async with subscriber(
                broker.port, f"{T}/availability", username="ptzd", password="s3cret pass"
            ) as live:
                await live.wait_for(f"{T}/availability", lambda m: m.payload == b"online")
        # a wrong password never connects, keeps retrying, and never crashes
        (creds / "mqtt-password").write_text("wrong")
        async with MqttBridge(cfg, CAM, environ=env) as bridge:
            await asyncio.sleep(0.5)
            assert not bridge.connected
            assert bridge.stats.connect_failures >= 2
    finally:
        broker.stop()


async def test_optional_bridge_disabled_is_none() -> None:
    async with optional_bridge(MqttConfig(), CAM) as bridge:
        assert bridge is None


async def test_tls_with_client_certificate(tmp_path: Path) -> None:
    tls = make_tls_files(tmp_path)
    broker = Broker(tmp_path, tls=tls)
    broker.start()
    try:
        cfg = fast_config(
            broker.url, ca_file=tls.ca, cert_file=tls.client_cert, key_file=tls.client_key
        )
        async with MqttBridge(cfg, CAM) as bridge:
            await connected_bridge(bridge)
            bridge.set_zoom_layer(1)
        assert bridge.stats.connects == 1
        # without the client certificate the broker refuses; the bridge retries, never crashes
        no_cert = fast_config(broker.url, ca_file=tls.ca, timeout_s=0.5)
        async with MqttBridge(no_cert, CAM) as bridge:
            await asyncio.sleep(1.0)
            assert not bridge.connected
            assert bridge.stats.connect_failures >= 1
        # a broker certificate from an unknown CA is refused
        async with MqttBridge(fast_config(broker.url), CAM) as bridge:
            await asyncio.sleep(0.5)
            assert not bridge.connected
    finally:
        broker.stop()


async def test_a_burst_of_rejections_reports_each(broker: Broker) -> None:
    async with (
        subscriber(broker.port, f"{T}/error") as errors,
        MqttBridge(fast_config(broker.url), CAM) as bridge,
    ):
        await connected_bridge(bridge)
        async with aiomqtt.Client("127.0.0.1", broker.port) as client:
            for i in range(5):
                await client.publish(f"{T}/ptz", f"bogus_{i}".encode(), qos=0)
        await errors.wait_for(f"{T}/error", lambda m: b"bogus_4" in m.payload)
        previews = [json.loads(m.payload)["payload_preview"] for m in errors.on(f"{T}/error")]
        assert previews == [f"bogus_{i}" for i in range(5)]
