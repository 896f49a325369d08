"""The simulated dome's end of the RS-485 line: a raw pty or a TCP port, with wire timing.

`SerialLink` is the transport-free core: bytes handed to `receive(data, t)` start crossing the
wire at `t` and take 10 bit times each (8N1) at the configured baud rate, as they would on a
real line, so a frame is decoded when its last byte has arrived. Frames come out of the
project's own `FrameParser` (Pelco-P and Pelco-D, resync after garbage) and are handed to the
dome at their arrival time on the injected clock. Replies go back to whoever sent the query.

`PtyEndpoint` owns a raw-mode pseudo-terminal and prints nothing itself (its `path` is what a
controller opens, like /dev/ttyUSB0). It keeps its own handle on the slave side, so the line
stays up when a controller closes the port and opens it again. `TcpEndpoint` listens for
`socket://HOST:PORT` clients (pyserial's URL handler), any number one after another or at once.
"""

from __future__ import annotations

import asyncio
import contextlib
import os
import pty
import tty
from collections import deque
from collections.abc import Callable
from dataclasses import dataclass

from ptzd.clock import Clock
from ptzd.logs import get_logger
from ptzd.pelco.codec import Frame, FrameParser

BITS_PER_BYTE = 10  # start + 8 data + stop
MAX_PENDING_FRAMES = 1024  # frames decoded but not yet due; more means the sender floods

Sink = Callable[[bytes], None]
FrameHandler = Callable[[Frame, float], bytes | None]

_log = get_logger("sim.serial")


@dataclass
class LinkCounters:
    bytes: int = 0
    frames: int = 0
    dropped_frames: int = 0  # frames lost because MAX_PENDING_FRAMES were already waiting
    replies: int = 0
    lost_replies: int = 0  # replies nobody could take (pty buffer full, client gone)


class SerialLink:
    """Wire timing + framing between a byte transport and the dome's frame handler."""

    def __init__(self, handler: FrameHandler, clock: Clock, *, baudrate: int) -> None:
        if baudrate <= 0:
            raise ValueError(f"baudrate must be positive, got {baudrate}")
        self._handler = handler
        self._clock = clock
        self.byte_time = BITS_PER_BYTE / baudrate
        self.parser = FrameParser()
        self.counters = LinkCounters()
        self._line_free_at = float("-inf")
        self._pending: deque[tuple[float, Frame, Sink | None]] = deque()
        self._wake = asyncio.Event()

    @property
    def bad_frames(self) -> int:
        """Frame-shaped byte runs rejected: wrong checksum, or Pelco-D address 0.

        Other bytes that belong to no frame are `parser.garbage_bytes`.
        """
        return self.parser.bad_checksums + self.parser.rejected_frames

    def receive(
        self, data: bytes, t: float, reply_to: Sink | None = None, *, ends_at: float | None = None
    ) -> None:
        """Bytes that started crossing the wire at `t` (or when the line is next free).

        `ends_at` instead pins the last byte's arrival (replaying a recorded line exactly).
        """
        arrival = max(t, self._line_free_at)
        pinned_end: float | None = None
        if ends_at is not None:
            start = ends_at - len(data) * self.byte_time
            if start >= self._line_free_at:
                arrival, pinned_end = start, ends_at
            else:  # the line is still busy: the bytes arrive later than recorded
                arrival = self._line_free_at
        for index, byte in enumerate(data):
            arrival += self.byte_time
            if pinned_end is not None and index == len(data) - 1:
                arrival = pinned_end
            self.counters.bytes += 1
            for frame in self.parser.feed(bytes((byte,))):
                self.counters.frames += 1
                if len(self._pending) >= MAX_PENDING_FRAMES:
                    self.counters.dropped_frames += 1
                    continue
                self._pending.append((arrival, frame, reply_to))
        self._line_free_at = arrival
        self._wake.set()

    async def run(self) -> None:
        """Deliver each decoded frame to the handler at its arrival time; runs until cancelled."""
        while True:
            while not self._pending:
                self._wake.clear()
                await self._wake.wait()
            arrival, frame, reply_to = self._pending.popleft()
            delay = arrival - self._clock.now()
            if delay > 0.0:
                await self._clock.sleep(delay)
            reply = self._handler(frame, arrival)
            if reply:
                self.counters.replies += 1
                if reply_to is None:
                    self.counters.lost_replies += 1
                else:
                    reply_to(reply)


class PtyEndpoint:
    """A raw-mode pty whose slave path a controller opens as its serial port."""

    def __init__(self, link: SerialLink, clock: Clock) -> None:
        self._link = link
        self._clock = clock
        self._master = -1
        self._slave = -1
        self.path = ""

    def open(self) -> str:
        """Create the pty, start reading it on the running loop; returns the slave path."""
        self._master, self._slave = pty.openpty()
        tty.setraw(self._slave)
        os.set_blocking(self._master, False)
        self.path = os.ttyname(self._slave)
        asyncio.get_running_loop().add_reader(self._master, self._readable)
        _log.info("pty_open", path=self.path)
        return self.path

    def _readable(self) -> None:
        try:
            data = os.read(self._master, 4096)
        except (BlockingIOError, InterruptedError):
            return
        except OSError as exc:  # EIO only if no slave handle is open; ours always is
            _log.warning("pty_read_failed", error=str(exc))
            return
        if data:
            self._link.receive(data, self._clock.now(), self._write)

    def _write(self, data: bytes) -> None:
        try:
            os.write(self._master, data)
        except OSError:
            self._link.counters.lost_replies += 1

    def close(self) -> None:
        if self._master >= 0:
            asyncio.get_running_loop().remove_reader(self._master)
            os.close(self._master)
            os.close(self._slave)
            self._master = self._slave = -1


class TcpEndpoint:
    """A TCP listener for `socket://HOST:PORT` controllers."""

    def __init__(self, link: SerialLink, clock: Clock, host: str, port: int) -> None:
        self._link = link
        self._clock = clock
        self._host = host
        self._port = port
        self._server: asyncio.Server | None = None
        self._clients: set[asyncio.StreamWriter] = set()
        self.address = ""

    async def open(self) -> str:
        """Start listening; returns `host:port` (the real port when 0 was asked for)."""
        self._server = await asyncio.start_server(self._client, self._host, self._port)
        host, port = self._server.sockets[0].getsockname()[:2]
        self.address = f"{host}:{port}"
        _log.info("tcp_listen", address=self.address)
        return self.address

    async def _client(self, reader: asyncio.StreamReader, writer: asyncio.StreamWriter) -> None:
        self._clients.add(writer)
        peer = writer.get_extra_info("peername")
        _log.info("tcp_client", peer=str(peer))

        def send(data: bytes) -> None:
            if writer.is_closing():
                self._link.counters.lost_replies += 1
            else:
                writer.write(data)

        try:
            while data := await reader.read(4096):
                self._link.receive(data, self._clock.now(), send)
        except ConnectionError:
            pass
        finally:
            self._clients.discard(writer)
            writer.close()
            _log.info("tcp_client_gone", peer=str(peer))

    async def close(self) -> None:
        if self._server is not None:
            self._server.close()
            for writer in list(self._clients):
                writer.close()
            with contextlib.suppress(Exception):
                await self._server.wait_closed()
            self._server = None
