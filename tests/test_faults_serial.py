"""Fault: the serial port vanishes and comes back.

Expected recovery (docs/reliability.md): the link notices the loss, reconnects with backoff,
and the first bytes on the new connection are STOP twice, then the motion still wanted --
never a stale motion from before the loss. Bounded: each test finishes in a few seconds.
"""

from __future__ import annotations

import asyncio
import contextlib
import os
import socket
import struct
import tty
from pathlib import Path

from ptzd.pelco.codec import FrameParser, Motion
from ptzd.pelco.link import PelcoLink
from tests.test_pelco_link import TcpPeer, cfg

STOP = Motion()


async def wait_until(predicate: object, limit_s: float = 5.0) -> None:
    """The state lives in another endpoint's counters: poll it (bounded)."""
    async with asyncio.timeout(limit_s):
        while not predicate():  # type: ignore[operator]  # noqa: ASYNC110
            await asyncio.sleep(0.02)


async def reset_connections(peer: TcpPeer) -> None:
    """Close every accepted socket with SO_LINGER 0: the link sees a TCP RST, not a FIN."""
    assert peer.server is not None
    peer.server.close()
    for writer in peer.writers:
        sock = writer.get_extra_info("socket")
        sock.setsockopt(socket.SOL_SOCKET, socket.SO_LINGER, struct.pack("ii", 1, 0))
        writer.transport.abort()
    peer.writers.clear()
    with contextlib.suppress(Exception):
        await peer.server.wait_closed()


async def test_tcp_reset_reconnects_and_sends_stop_then_fresh_motion() -> None:
    first = TcpPeer()
    await first.start()
    port = first.port
    config = cfg(f"socket://127.0.0.1:{port}", reconnect_min_s=0.05, reconnect_max_s=0.2)
    second = TcpPeer()
    try:
        async with PelcoLink(config, seed=3) as link:
            link.send(Motion(pan=20))
            await wait_until(lambda: Motion(pan=20) in [f.command for f in first.frames])
            await reset_connections(first)
            await wait_until(lambda: not link.connected)
            link.send(Motion(pan=-7))  # wanted while the port is gone: the latest wins
            await second.start(port)
            await wait_until(lambda: len(second.frames) >= 3)
            assert link.counters.reconnects == 1
        await wait_until(lambda: len(second.frames) >= 5)
    finally:
        await second.stop()
    assert [f.command for f in second.frames] == [STOP, STOP, Motion(pan=-7), STOP, STOP]


class PtyBehindSymlink:
    """A pty reached through a stable symlink, like /dev/serial/by-id/...: `unplug` closes
    the pty (the link reads EOF/EIO), `replug` makes a new one behind the same name."""

    def __init__(self, link_path: Path) -> None:
        self.path = link_path
        self.master = -1
        self.slave = -1
        self.parser = FrameParser()

    def replug(self) -> None:
        self.master, self.slave = os.openpty()
        tty.setraw(self.slave)
        os.set_blocking(self.master, False)
        tmp = self.path.with_suffix(".new")
        tmp.unlink(missing_ok=True)
        tmp.symlink_to(os.ttyname(self.slave))
        tmp.replace(self.path)

    def unplug(self) -> None:
        self.path.unlink()
        os.close(self.slave)
        os.close(self.master)
        self.master = self.slave = -1

    def motions(self) -> list[Motion]:
        data = b""
        with contextlib.suppress(BlockingIOError, OSError):
            while chunk := os.read(self.master, 65536):
                data += chunk
        return [f.command for f in self.parser.feed(data) if isinstance(f.command, Motion)]

    def collect(self, into: list[Motion]) -> list[Motion]:
        """Append the motions read so far to `into` and return it."""
        into += self.motions()
        return into


async def test_pty_closed_and_reopened_reconnects_with_stop_first(tmp_path: Path) -> None:
    port = PtyBehindSymlink(tmp_path / "ttyPTZ")
    port.replug()
    config = cfg(str(port.path), reconnect_min_s=0.05, reconnect_max_s=0.2, keepalive_s=0.5)
    seen: list[Motion] = []
    try:
        async with PelcoLink(config, seed=4) as link:
            link.send(Motion(tilt=9))
            await wait_until(lambda: Motion(tilt=9) in port.collect(seen))
            port.unplug()
            # writes (keep-alives) or the reader hit the closed pty
            await wait_until(lambda: not link.connected)
            link.send(Motion(tilt=-4))
            await asyncio.sleep(0.3)  # the device stays away for a while: retries fail
            assert not link.connected
            port.replug()
            after: list[Motion] = []
            await wait_until(lambda: len(port.collect(after)) >= 3)
            assert after[:3] == [STOP, STOP, Motion(tilt=-4)]
            assert link.counters.reconnects >= 1
    finally:
        if port.master >= 0:
            port.unplug()
