"""Frame-to-MQTT latency and publish rate of `MqttBridge`, against raw paho-mqtt as the peer.

Starts a private mosquitto on a free loopback port. A paho subscriber (its own network
thread) timestamps every `track` message on arrival; latency is arrival minus the moment
the producer handed the message over (`MqttBridge.publish_track` / paho `publish`),
on the same monotonic clock. Then each publisher is driven as fast as it will go.

    .venv/bin/python bench/mqtt_latency.py [--messages 400] [--rate-hz 100]

Prints a table and writes bench/results/mqtt_latency.json. This machine is 2 shared cores:
numbers are noisy; quote medians of repeated runs.
"""

from __future__ import annotations

import argparse
import asyncio
import json
import statistics
import sys
import tempfile
import threading
import time
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import paho.mqtt.client as paho
from paho.mqtt.enums import CallbackAPIVersion

REPO = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(REPO))

from ptzd.mqtt.bridge import MqttBridge  # noqa: E402
from ptzd.mqtt.config import mqtt_config_from_url  # noqa: E402
from ptzd.mqtt.messages import TrackMessage, TrackState  # noqa: E402
from tests.mqtt_helpers import Broker  # noqa: E402

RESULTS = REPO / "bench" / "results" / "mqtt_latency.json"
TOPIC = "ptzd/bench/track"


@dataclass
class Arrivals:
    """Arrival time per message id, filled by paho's network thread."""

    times: dict[int, float] = field(default_factory=dict)
    count: int = 0
    lock: threading.Lock = field(default_factory=threading.Lock)
    done: threading.Event = field(default_factory=threading.Event)
    expect: int = 0

    def reset(self, expect: int) -> None:
        with self.lock:
            self.times.clear()
            self.count = 0
            self.expect = expect
            self.done.clear()

    def on_message(self, _c: Any, _u: Any, msg: paho.MQTTMessage) -> None:
        now = time.perf_counter()
        ident = json.loads(msg.payload)["id"]
        with self.lock:
            self.times[ident] = now
            self.count += 1
            if self.expect and self.count >= self.expect:
                self.done.set()


def make_track(ident: int) -> TrackMessage:
    return TrackMessage(
        ts=time.time(),
        state=TrackState.TRACKING,
        frame_size=(640, 480),
        id=ident,
        bbox=(300.0, 200.0, 48.0, 96.0),
        confidence=0.9,
        velocity=(4.0, -1.0),
    )


def summary(latencies_s: list[float]) -> dict[str, float]:
    ms = sorted(v * 1000.0 for v in latencies_s)
    if not ms:
        return {"n": 0}
    p99 = ms[min(len(ms) - 1, round(0.99 * (len(ms) - 1)))]
    return {"n": len(ms), "p50_ms": statistics.median(ms), "p99_ms": p99, "max_ms": ms[-1]}


def paho_client(port: int, name: str) -> paho.Client:
    client = paho.Client(CallbackAPIVersion.VERSION2, client_id=name)
    client.connect("127.0.0.1", port)
    client.loop_start()
    return client


async def bridge_latency(url: str, arrivals: Arrivals, n: int, rate_hz: float) -> dict[str, Any]:
    cfg = mqtt_config_from_url(url, prefix="ptzd", track_rate_hz=1000.0)
    sent: dict[int, float] = {}
    async with MqttBridge(cfg, "bench") as bridge:
        await asyncio.wait_for(bridge.wait_connected(), 10)
        arrivals.reset(n)
        for i in range(n):
            msg = make_track(i)
            sent[i] = time.perf_counter()
            bridge.publish_track(msg)
            await asyncio.sleep(1.0 / rate_hz)
        await asyncio.to_thread(arrivals.done.wait, 5.0)
    with arrivals.lock:
        lat = [arrivals.times[i] - sent[i] for i in sent if i in arrivals.times]
    return {**summary(lat), "lost": n - len(lat)}


def paho_latency(port: int, arrivals: Arrivals, n: int, rate_hz: float) -> dict[str, Any]:
    client = paho_client(port, "bench-paho-pub")
    sent: dict[int, float] = {}
    try:
        arrivals.reset(n)
        for i in range(n):
            payload = make_track(i).to_payload()
            sent[i] = time.perf_counter()
            client.publish(TOPIC, payload, qos=0)
            time.sleep(1.0 / rate_hz)
        arrivals.done.wait(5.0)
    finally:
        client.loop_stop()
        client.disconnect()
    with arrivals.lock:
        lat = [arrivals.times[i] - sent[i] for i in sent if i in arrivals.times]
    return {**summary(lat), "lost": n - len(lat)}


async def bridge_max_rate(url: str, arrivals: Arrivals, seconds: float) -> dict[str, Any]:
    """Producer calls publish_track as fast as the loop lets it; the bridge sends what its
    1000 Hz cap and the broker allow (the rest is coalesced, by design)."""
    cfg = mqtt_config_from_url(url, prefix="ptzd", track_rate_hz=1000.0)
    async with MqttBridge(cfg, "bench") as bridge:
        await asyncio.wait_for(bridge.wait_connected(), 10)
        arrivals.reset(0)
        start = time.perf_counter()
        calls = 0
        while time.perf_counter() - start < seconds:
            bridge.publish_track(make_track(calls))
            calls += 1
            if calls % 10 == 0:
                await asyncio.sleep(0)
        elapsed = time.perf_counter() - start
        await asyncio.sleep(0.3)
        published = bridge.stats.tracks_published
    with arrivals.lock:
        received = arrivals.count
    return {
        "calls_per_s": calls / elapsed,
        "published_per_s": published / elapsed,
        "received_per_s": received / elapsed,
        "coalesced": bridge.stats.tracks_coalesced,
    }


def paho_max_rate(port: int, arrivals: Arrivals, n: int) -> dict[str, Any]:
    client = paho_client(port, "bench-paho-rate")
    try:
        payloads = [make_track(i).to_payload() for i in range(n)]
        arrivals.reset(n)
        start = time.perf_counter()
        for payload in payloads:
            client.publish(TOPIC, payload, qos=0)
        arrivals.done.wait(30.0)
        elapsed = time.perf_counter() - start
    finally:
        client.loop_stop()
        client.disconnect()
    with arrivals.lock:
        received = arrivals.count
    return {
        "published_per_s": n / elapsed,
        "received_per_s": received / elapsed,
        "lost": n - received,
    }


async def run(args: argparse.Namespace) -> dict[str, Any]:
    with tempfile.TemporaryDirectory() as tmp:
        broker = Broker(Path(tmp))
        broker.start()
        arrivals = Arrivals()
        sub = paho_client(broker.port, "bench-sub")
        sub.on_message = arrivals.on_message
        sub.subscribe(TOPIC, qos=0)
        await asyncio.sleep(0.3)  # SUBACK
        try:
            results: dict[str, Any] = {
                "messages": args.messages,
                "rate_hz": args.rate_hz,
                "latency": {
                    "bridge": await bridge_latency(
                        broker.url, arrivals, args.messages, args.rate_hz
                    ),
                    "paho": await asyncio.to_thread(
                        paho_latency, broker.port, arrivals, args.messages, args.rate_hz
                    ),
                },
                "max_rate": {
                    "bridge": await bridge_max_rate(broker.url, arrivals, args.seconds),
                    "paho": await asyncio.to_thread(
                        paho_max_rate, broker.port, arrivals, args.burst
                    ),
                },
            }
        finally:
            sub.loop_stop()
            sub.disconnect()
            broker.stop()
    return results


def print_table(results: dict[str, Any]) -> None:
    print(f"publish-to-receive latency, {results['messages']} msgs at {results['rate_hz']} Hz")
    print(f"{'publisher':<10} {'p50 ms':>8} {'p99 ms':>8} {'max ms':>8} {'lost':>5}")
    for name, r in results["latency"].items():
        print(
            f"{name:<10} {r.get('p50_ms', float('nan')):8.3f} {r.get('p99_ms', float('nan')):8.3f}"
            f" {r.get('max_ms', float('nan')):8.3f} {r['lost']:>5}"
        )
    print("max publish rate (messages/s)")
    print(f"{'publisher':<10} {'published':>10} {'received':>10}")
    for name, r in results["max_rate"].items():
        print(f"{name:<10} {r['published_per_s']:10.0f} {r['received_per_s']:10.0f}")
    print("(bridge is capped at track_rate_hz=1000 and coalesces by design; 2 shared cores: noisy)")


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--messages", type=int, default=400)
    parser.add_argument("--rate-hz", type=float, default=100.0)
    parser.add_argument("--seconds", type=float, default=2.0, help="bridge max-rate run")
    parser.add_argument("--burst", type=int, default=20000, help="paho max-rate messages")
    args = parser.parse_args()
    results = asyncio.run(run(args))
    print_table(results)
    RESULTS.parent.mkdir(parents=True, exist_ok=True)
    RESULTS.write_text(json.dumps(results, indent=2) + "\n")
    print(f"wrote {RESULTS.relative_to(REPO)}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
