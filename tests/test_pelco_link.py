"""PelcoLink over a real raw-mode pty and over socket:// to a local TCP server."""

from __future__ import annotations

import asyncio
import contextlib
import itertools
import os
import time
import tty
from collections.abc import AsyncIterator, Iterator
from typing import Any

import pytest

from ptzd.clock import VirtualClock
from ptzd.pelco.codec import (
    Frame,
    FrameParser,
    Motion,
    PelcoProtocol,
    Preset,
    PresetAction,
    encode,
)
from ptzd.pelco.config import SerialConfig
from ptzd.pelco.link import LinkError, PelcoLink, frame_time

STOP = Motion()


class PtyPeer:
    """The dome's end of a raw pty: timestamps every frame as it arrives."""

    def __init__(self) -> None:
        self.master, self.slave = os.openpty()
        tty.setraw(self.slave)
        os.set_blocking(self.master, False)
        self.path = os.ttyname(self.slave)
        self.parser = FrameParser()
        self.arrivals: list[tuple[float, Frame]] = []
        asyncio.get_running_loop().add_reader(self.master, self._readable)

    def _readable(self) -> None:
        with contextlib.suppress(BlockingIOError):
            data = os.read(self.master, 4096)
            now = time.monotonic()
            self.arrivals += [(now, f) for f in self.parser.feed(data)]

    @property
    def commands(self) -> list[Any]:
        return [f.command for _, f in self.arrivals]

    def close(self) -> None:
        asyncio.get_running_loop().remove_reader(self.master)
        os.close(self.master)
        os.close(self.slave)


@contextlib.contextmanager
def pty_peer() -> Iterator[PtyPeer]:
    peer = PtyPeer()
    try:
        yield peer
    finally:
        peer.close()


def cfg(port: str, **overrides: Any) -> SerialConfig:
    return SerialConfig(port=port, **overrides)


async def test_stop_twice_on_open_and_on_close() -> None:
    with pty_peer() as peer:
        async with PelcoLink(cfg(peer.path)) as link:
            await asyncio.sleep(0.3)
            assert peer.commands == [STOP, STOP]
            link.send(Motion(pan=10))
            await asyncio.sleep(0.2)
        await asyncio.sleep(0.1)
    assert peer.commands == [STOP, STOP, Motion(pan=10), STOP, STOP]
    assert link.counters.frames_sent == 5


async def test_pacing_at_4800_baud_never_beats_the_wire_plus_gap() -> None:
    with pty_peer() as peer:
        config = cfg(peer.path, baudrate=4800, min_gap_s=0.02)
        async with PelcoLink(config) as link:
            await asyncio.sleep(0.2)
            for i in range(1, 16):
                link.send(Motion(pan=i))
                await asyncio.sleep(0.004)  # 250 commands/s, far faster than the wire
            await asyncio.sleep(0.3)
    times = [t for t, f in peer.arrivals]
    spacing = min(b - a for a, b in itertools.pairwise(times))
    wire = frame_time(8, config)  # 8 bytes x 10 bits / 4800 = 16.7 ms
    assert wire == pytest.approx(8 * 10 / 4800)
    # arrival jitter on a loaded 2-core box: allow 5 ms early
    assert spacing >= wire + config.min_gap_s - 0.005
    motions = [c for c in peer.commands if c != STOP]
    assert motions[-1] == Motion(pan=15)  # the newest always gets through
    assert len(motions) < 15  # the rest were coalesced, not queued
    assert link.counters.coalesced == 15 - len(motions)


async def test_coalescing_keeps_presets_and_their_order() -> None:
    with pty_peer() as peer:
        async with PelcoLink(cfg(peer.path)) as link:
            await asyncio.sleep(0.25)
            link.send(Motion(pan=1))
            link.send(Motion(pan=2))
            link.send(Preset(PresetAction.SET, 4))
            link.send(Motion(pan=3))
            link.send(Preset(PresetAction.GOTO, 4))
            link.send(Motion(pan=5))
            await asyncio.sleep(0.6)
            sent = peer.commands[2:]
    # motions 1, 2 and 3 were superseded before reaching the wire; presets are never dropped
    assert sent == [Preset(PresetAction.SET, 4), Preset(PresetAction.GOTO, 4), Motion(pan=5)]
    assert link.counters.coalesced == 3


async def test_sends_on_change_and_keeps_alive_while_moving() -> None:
    with pty_peer() as peer:
        config = cfg(peer.path, keepalive_s=0.3, deadman_s=5.0)
        async with PelcoLink(config) as link:
            await asyncio.sleep(0.2)
            for _ in range(10):
                link.send(Motion(tilt=7))  # the same command: one frame, not ten
                await asyncio.sleep(0.1)
            assert link.counters.unchanged == 9
    moving = [c for c in peer.commands if c == Motion(tilt=7)]
    assert 3 <= len(moving) <= 5  # 1 + keep-alives every 0.3 s over ~1 s
    assert link.counters.keepalives == len(moving) - 1


async def test_deadman_stops_a_dome_left_moving() -> None:
    with pty_peer() as peer:
        async with PelcoLink(cfg(peer.path, deadman_s=0.4, keepalive_s=0.2)) as link:
            await asyncio.sleep(0.15)
            link.send(Motion(pan=30))
            start = time.monotonic()
            await asyncio.sleep(0.8)  # nobody refreshes the command
            stops = [t for t, f in peer.arrivals if f.command == STOP and t > start]
            assert len(stops) == 2
            assert 0.35 <= stops[0] - start <= 0.6
            assert link.counters.deadman_stops == 1
            assert link.wire_motion == STOP


async def test_cancellation_sends_stop() -> None:
    with pty_peer() as peer:

        async def operator() -> None:
            async with PelcoLink(cfg(peer.path)) as link:
                await asyncio.sleep(0.2)
                link.send(Motion(pan=-50, tilt=20))
                await asyncio.sleep(10)

        task = asyncio.create_task(operator())
        await asyncio.sleep(0.5)
        task.cancel()
        with pytest.raises(asyncio.CancelledError):
            await task
        await asyncio.sleep(0.1)
    assert peer.commands[-3:] == [Motion(pan=-50, tilt=20), STOP, STOP]


async def test_event_loop_stays_responsive_while_writing() -> None:
    with pty_peer() as peer:
        async with PelcoLink(cfg(peer.path, baudrate=2400, min_gap_s=0.0)) as link:
            lags: list[float] = []
            for i in range(300):
                link.send(Motion(pan=(i % 60) + 1))
                before = time.perf_counter()
                await asyncio.sleep(0.002)
                lags.append(time.perf_counter() - before - 0.002)
    lags.sort()
    assert lags[len(lags) // 2] < 0.005  # median lag: the loop never waits on the port
    assert link.counters.frames_sent >= 10


async def test_open_failure_is_a_clear_error() -> None:
    with pytest.raises(LinkError) as info:
        async with PelcoLink(cfg("/dev/does-not-exist-ptzd")):
            pass
    assert "/dev/does-not-exist-ptzd" in str(info.value)


async def test_send_outside_the_context_is_refused() -> None:
    link = PelcoLink(cfg("loop://"))
    with pytest.raises(LinkError):
        link.send(STOP)


# --- socket:// -----------------------------------------------------------------------------


class TcpPeer:
    """A local TCP server standing in for a serial-over-IP adapter."""

    def __init__(self) -> None:
        self.parser = FrameParser()
        self.frames: list[Frame] = []
        self.connections = 0
        self.writers: list[asyncio.StreamWriter] = []
        self.server: asyncio.Server | None = None
        self.port = 0

    async def start(self, port: int = 0) -> None:
        self.server = await asyncio.start_server(self._client, "127.0.0.1", port)
        self.port = self.server.sockets[0].getsockname()[1]

    async def _client(self, reader: asyncio.StreamReader, writer: asyncio.StreamWriter) -> None:
        self.connections += 1
        self.writers.append(writer)
        with contextlib.suppress(ConnectionError):
            while data := await reader.read(4096):
                self.frames += self.parser.feed(data)

    async def stop(self) -> None:
        assert self.server is not None
        self.server.close()
        for writer in self.writers:
            writer.close()
        self.writers.clear()
        with contextlib.suppress(Exception):
            await self.server.wait_closed()


@contextlib.asynccontextmanager
async def tcp_peer() -> AsyncIterator[TcpPeer]:
    peer = TcpPeer()
    await peer.start()
    try:
        yield peer
    finally:
        await peer.stop()


async def test_socket_url_and_replies_come_back_decoded() -> None:
    received: list[Frame] = []
    async with tcp_peer() as peer:
        url = f"socket://127.0.0.1:{peer.port}"
        async with PelcoLink(cfg(url, protocol="d"), on_frame=received.append) as link:
            await asyncio.sleep(0.3)
            reply = encode(Motion(pan=3), protocol=PelcoProtocol.D, address=1)
            peer.writers[0].write(b"\x13" + reply)  # garbage, then a frame
            link.send(Motion(pan=-9))
            await asyncio.sleep(0.3)
        assert [f.command for f in peer.frames][:3] == [STOP, STOP, Motion(pan=-9)]
    assert [f.command for f in received] == [Motion(pan=3)]
    assert link.counters.frames_received == 1
    assert link.counters.bad_bytes_received == 1


async def test_reconnects_after_the_peer_disappears() -> None:
    peer = TcpPeer()
    await peer.start()
    url = f"socket://127.0.0.1:{peer.port}"
    config = cfg(url, reconnect_min_s=0.05, reconnect_max_s=0.2, deadman_s=10.0)
    try:
        async with PelcoLink(config, seed=1) as link:
            await asyncio.sleep(0.2)
            link.send(Motion(pan=12))
            await asyncio.sleep(0.2)
            port = peer.port
            await peer.stop()  # the adapter goes away (TCP reset)
            await asyncio.sleep(0.3)
            assert not link.connected
            link.send(Motion(pan=13))  # accepted while down: latest wins
            peer = TcpPeer()
            await peer.start(port)
            await asyncio.sleep(1.0)  # backoff is at most 0.2 s
            assert link.counters.reconnects == 1
            assert link.counters.port_errors >= 1
    finally:
        await peer.stop()
    # back on the line: STOP twice, then the motion still wanted, then STOP twice on close
    assert [f.command for f in peer.frames] == [STOP, STOP, Motion(pan=13), STOP, STOP]


async def test_virtual_clock_keepalive_and_deadman_are_exact_over_loop_url() -> None:
    """On the simulator's virtual clock the link's timing is exact and takes no real time."""
    clock = VirtualClock()
    started = time.monotonic()
    config = cfg("loop://", keepalive_s=1.0, deadman_s=3.5, min_gap_s=0.05)
    async with PelcoLink(config, clock=clock) as link:
        await clock.run_until(0.5)
        link.send(Motion(pan=5))
        await clock.run_until(20.0)
        counters = link.counters
        # open: STOP x2; the motion; keep-alives at 1.5, 2.5, 3.5; dead-man at 4.0: STOP x2
        assert (counters.frames_sent, counters.keepalives, counters.deadman_stops) == (8, 3, 1)
        assert link.wire_motion == STOP
    assert time.monotonic() - started < 5.0
