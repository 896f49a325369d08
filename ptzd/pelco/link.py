"""The serial link to the dome: the only Pelco code that does I/O.

``async with PelcoLink(config) as link: link.send(Motion(pan=20))``

- `send` never blocks and never waits: motion is latest-wins (a motion not yet on the wire is
  replaced by a newer one and counted as `coalesced`; stale motion is never queued). Other
  commands (presets, zoom speed, queries) keep their order and are never dropped.
- Frames are paced: the next frame starts no earlier than the previous one's wire time
  (bytes x bits per byte / baud) plus `min_gap_s`. A motion equal to the one in force is not
  resent (sends on change); while the dome moves, the motion in force is repeated every
  `keepalive_s`; a STOP is repeated once, `keepalive_s` later.
- Dead-man: when no fresh motion command arrived for `deadman_s` while the dome moves, the
  link sends STOP twice by itself. STOP twice also on open, on reconnect and on close
  (also when the task is cancelled; those closing STOPs are paced in real time).
- When the port vanishes (USB unplug, TCP reset, pty closed) the link logs it, reconnects
  with jittered exponential backoff and sends STOP twice once it is back.

I/O design (docs/protocol.md has the reasoning): the port is opened with pyserial in
non-blocking mode; frames (at most 8 bytes) are written from the event loop with a single
non-blocking write, after waiting for writability with `loop.add_writer` when the port has a
file descriptor; replies are read with `loop.add_reader`. Only opening and closing the port,
which can block (TCP connect, tty drain on close), run in a worker thread. Timing uses the
injected `Clock`, so the link runs unchanged on the simulator's virtual clock.
"""

from __future__ import annotations

import asyncio
import contextlib
import random
from collections import deque
from collections.abc import Callable
from dataclasses import dataclass
from types import TracebackType
from typing import Any, Self

import serial

from ptzd.backoff import backoff_delay
from ptzd.clock import Clock, RealClock
from ptzd.errors import PtzdError
from ptzd.logs import get_logger
from ptzd.pelco.codec import STOP, Command, Frame, FrameParser, Motion, PelcoProtocol, encode
from ptzd.pelco.config import SerialConfig

MAX_QUEUED = 256  # non-motion commands waiting for the wire; more means the caller floods
CLOSE_DRAIN_S = 1.0  # how long closing waits for the final STOPs to leave

_log = get_logger("pelco.link")

_PARITY = {"none": serial.PARITY_NONE, "even": serial.PARITY_EVEN, "odd": serial.PARITY_ODD}
_STOPBITS = {1: serial.STOPBITS_ONE, 2: serial.STOPBITS_TWO}


class LinkError(PtzdError):
    """The link cannot do what was asked: port cannot be opened, link not open, queue full."""

    def __init__(self, port: str, reason: str) -> None:
        self.port = port
        self.reason = reason
        super().__init__(f"{port}: {reason}")


class _PortLostError(Exception):
    """The port failed under us; the supervisor reconnects."""


@dataclass
class LinkCounters:
    commands: int = 0  # send() calls
    frames_sent: int = 0
    bytes_sent: int = 0
    coalesced: int = 0  # motions replaced by a newer one before reaching the wire
    unchanged: int = 0  # motions equal to the one in force (not resent)
    keepalives: int = 0
    deadman_stops: int = 0
    reconnects: int = 0  # successful re-opens after the port vanished
    port_errors: int = 0
    frames_received: int = 0
    bad_bytes_received: int = 0  # garbage and corrupted frames coming back from the line


@dataclass(frozen=True, slots=True)
class _Item:
    command: Command
    coalescable: bool  # a motion a newer motion may replace


def frame_time(n_bytes: int, config: SerialConfig) -> float:
    """Seconds `n_bytes` occupy the wire at the configured baud rate and framing."""
    return n_bytes * config.bits_per_byte / config.effective_baudrate


class PelcoLink:
    """Paced, coalescing, self-stopping Pelco writer over a pyserial URL."""

    def __init__(
        self,
        config: SerialConfig,
        *,
        clock: Clock | None = None,
        on_frame: Callable[[Frame], None] | None = None,
        seed: int | None = None,
    ) -> None:
        self.config = config
        self.protocol = PelcoProtocol(config.protocol)
        self.counters = LinkCounters()
        self.parser = FrameParser()
        self._clock: Clock = clock if clock is not None else RealClock()
        self._on_frame = on_frame
        # reconnect jitter; seed None = OS entropy, so domes on one network do not retry in step
        self._rng = random.Random(seed)
        self._port: serial.SerialBase | None = None
        self._queue: deque[_Item] = deque()
        self._wire_motion: Motion | None = None  # motion in force on the dome; None = unknown
        # the command being written right now: once written it is what the dome does, so a new
        # motion equal to the old wire state is still a change (e.g. STOP after a move mid-write)
        self._writing: Command | None = None
        self._wanted: Motion = STOP  # the newest motion asked for
        self._fresh_at = -float("inf")  # clock time of the newest send(Motion)
        self._last_frame_at = -float("inf")
        self._line_free_at = -float("inf")
        self._wake = asyncio.Event()
        self._task: asyncio.Task[None] | None = None
        self._open = False
        self._lost: BaseException | None = None  # set by the reader when the port dies
        self._repeat_stop = False  # one keep-alive repeat of a STOP is still due

    # --- public API ----------------------------------------------------------------------

    @property
    def connected(self) -> bool:
        return self._port is not None

    @property
    def idle(self) -> bool:
        """Nothing queued and nothing being written: everything sent has left the link."""
        return not self._queue and self._writing is None

    @property
    def wire_motion(self) -> Motion | None:
        """The motion last put on the wire (None after a preset or before the first frame)."""
        return self._wire_motion

    def send(self, command: Command) -> None:
        """Hand a command to the link; returns at once (see the module doc for the rules)."""
        if not self._open:
            raise LinkError(self.config.port, "link is not open")
        task = self._task
        if task is not None and task.done():  # a bug killed the writer: fail loudly
            error = None if task.cancelled() else task.exception()
            raise LinkError(self.config.port, f"writer task ended: {error!r}")
        self.counters.commands += 1
        if isinstance(command, Motion):
            self._wanted = command
            self._fresh_at = self._clock.now()
            self._enqueue_motion(command)
        else:
            if len(self._queue) >= MAX_QUEUED:
                raise LinkError(self.config.port, f"{MAX_QUEUED} commands already waiting")
            self._queue.append(_Item(command, coalescable=False))
        self._wake.set()

    async def __aenter__(self) -> Self:
        try:
            self._port = await asyncio.to_thread(self._open_port)
        except (serial.SerialException, OSError, ValueError) as exc:
            raise LinkError(self.config.port, f"cannot open: {exc}") from None
        self._open = True
        _log.info(
            "port_open",
            port=self.config.port,
            protocol=str(self.protocol),
            baudrate=self.config.effective_baudrate,
            address=self.config.address,
        )
        self._start_reader()
        self._queue_stop_twice()
        self._task = asyncio.create_task(self._run(), name="pelco-link")
        return self

    async def __aexit__(
        self,
        exc_type: type[BaseException] | None,
        exc: BaseException | None,
        tb: TracebackType | None,
    ) -> None:
        self._open = False
        if self._task is not None:
            self._task.cancel()
            with contextlib.suppress(asyncio.CancelledError, Exception):
                await self._task
            self._task = None
        try:
            await self._final_stop()
        finally:
            await self._close_port()

    # --- queueing ------------------------------------------------------------------------

    def _enqueue_motion(self, motion: Motion) -> None:
        replaced = [item for item in self._queue if item.coalescable]
        if replaced:
            self.counters.coalesced += len(replaced)
            self._queue = deque(item for item in self._queue if not item.coalescable)
        if motion == self._motion_after_queue():
            if not replaced:
                self.counters.unchanged += 1
            return
        self._queue.append(_Item(motion, coalescable=True))

    def _motion_after_queue(self) -> Motion | None:
        """The motion in force once everything queued is sent (None = unknown)."""
        if not self._queue:
            if self._writing is not None:
                return self._writing if isinstance(self._writing, Motion) else None
            return self._wire_motion
        last = self._queue[-1].command
        return last if isinstance(last, Motion) else None

    def _queue_stop_twice(self) -> None:
        self._queue = deque(item for item in self._queue if not item.coalescable)
        self._queue.appendleft(_Item(STOP, coalescable=False))
        self._queue.appendleft(_Item(STOP, coalescable=False))

    def _next_item(self, now: float) -> tuple[_Item | None, float]:
        """What to send now, or (None, when to look again)."""
        if self._queue:
            return self._queue[0], now
        wire = self._wire_motion
        if wire is not None and wire != STOP:
            deadman_at = self._fresh_at + self.config.deadman_s
            if now >= deadman_at:
                self.counters.deadman_stops += 1
                _log.warning("deadman_stop", idle_s=round(now - self._fresh_at, 3))
                self._wanted = STOP
                self._queue_stop_twice()
                return self._queue[0], now
            keepalive_at = self._last_frame_at + self.config.keepalive_s
            if now >= keepalive_at:
                self.counters.keepalives += 1
                return _Item(wire, coalescable=True), now
            return None, min(deadman_at, keepalive_at)
        if wire == STOP and self._repeat_stop:
            # a lost STOP is the dangerous loss: repeat it once, then stay quiet so the
            # link does not fight a keyboard sharing the bus while autotracking is off
            repeat_at = self._last_frame_at + self.config.keepalive_s
            if now >= repeat_at:
                self._repeat_stop = False
                self.counters.keepalives += 1
                return _Item(STOP, coalescable=True), now
            return None, repeat_at
        return None, float("inf")

    # --- the writer task -----------------------------------------------------------------

    async def _run(self) -> None:
        failures = 0
        while True:
            try:
                await self._serve()
            except _PortLostError as exc:
                self.counters.port_errors += 1
                _log.warning("port_lost", port=self.config.port, error=str(exc.__cause__ or exc))
                await self._close_port()
            while self._port is None:
                delay = backoff_delay(
                    failures, self.config.reconnect_min_s, self.config.reconnect_max_s, self._rng
                )
                await self._clock.sleep(delay)
                try:
                    self._port = await asyncio.to_thread(self._open_port)
                except (serial.SerialException, OSError, ValueError) as exc:
                    failures += 1
                    _log.info("reconnect_failed", port=self.config.port, error=str(exc))
                    continue
                failures = 0
                self.counters.reconnects += 1
                _log.warning("port_reconnected", port=self.config.port)
                self._start_reader()
                self._wire_motion = None
                self._line_free_at = -float("inf")
                self._queue_stop_twice()
                now = self._clock.now()
                if self._wanted != STOP and now - self._fresh_at < self.config.deadman_s:
                    self._queue.append(_Item(self._wanted, coalescable=True))

    async def _serve(self) -> None:
        while True:
            if self._lost is not None:
                lost, self._lost = self._lost, None
                raise _PortLostError(str(lost)) from lost
            now = self._clock.now()
            if now < self._line_free_at:
                await self._clock.sleep(self._line_free_at - now)
                continue  # newer commands may have arrived meanwhile: decide again
            item, wake_at = self._next_item(now)
            if item is None:
                await self._wait(wake_at - now)
                continue
            if self._queue and self._queue[0] is item:
                self._queue.popleft()
            self._writing = item.command
            try:
                await self._write_frame(item.command)
            finally:
                self._writing = None

    async def _wait(self, seconds: float) -> None:
        """Until `send` is called or `seconds` of clock time passed."""
        self._wake.clear()
        if self._queue or self._lost is not None:
            return
        waiter = asyncio.ensure_future(self._wake.wait())
        if seconds == float("inf"):
            await waiter
            return
        sleeper = asyncio.ensure_future(self._clock.sleep(max(0.0, seconds)))
        try:
            await asyncio.wait((waiter, sleeper), return_when=asyncio.FIRST_COMPLETED)
        finally:
            waiter.cancel()
            sleeper.cancel()

    async def _write_frame(self, command: Command) -> None:
        data = encode(command, protocol=self.protocol, address=self.config.address)
        port = self._port
        if port is None:
            raise _PortLostError("port closed")
        try:
            await self._write_all(port, data)
        except (serial.SerialException, OSError) as exc:
            raise _PortLostError(str(exc)) from exc
        now = self._clock.now()
        self._last_frame_at = now
        self._line_free_at = now + frame_time(len(data), self.config) + self.config.min_gap_s
        self.counters.frames_sent += 1
        self.counters.bytes_sent += len(data)
        if isinstance(command, Motion):
            self._repeat_stop = command == STOP and self._wire_motion != STOP
            self._wire_motion = command
        else:
            self._wire_motion = None  # a preset or position command moves the dome by itself

    async def _write_all(self, port: serial.SerialBase, data: bytes) -> None:
        """Write `data` without blocking the loop: wait for writability, write what fits."""
        fd = _fileno(port)
        view = memoryview(data)
        while view:
            if fd is not None:
                await _writable(fd)
            written = port.write(bytes(view))
            view = view[written or 0 :]

    # --- port handling -------------------------------------------------------------------

    def _open_port(self) -> serial.SerialBase:
        """Blocking: runs in a worker thread."""
        cfg = self.config
        port = serial.serial_for_url(
            cfg.port,
            baudrate=cfg.effective_baudrate,
            bytesize=cfg.bytesize,
            parity=_PARITY[cfg.parity],
            stopbits=_STOPBITS[cfg.stopbits],
            timeout=0,
            write_timeout=0,
        )
        if _fileno(port) is None:
            # no descriptor to wait on (loop://): its writes only append to a queue, and
            # its emulated write timeout of 0 would fail every write
            port.write_timeout = None
        return port

    def _start_reader(self) -> None:
        port = self._port
        if port is None:
            return
        fd = _fileno(port)
        if fd is None:
            return
        asyncio.get_running_loop().add_reader(fd, self._readable, port)

    def _readable(self, port: serial.SerialBase) -> None:
        try:
            data = port.read(4096)
        except (serial.SerialException, OSError) as exc:
            self._stop_reader(port)
            if self._task is not None and self._port is port:
                # wake the writer: its next write fails and it reconnects
                self._lost_while_idle(exc)
            return
        if not data:
            return
        before = self.parser.garbage_bytes
        for frame in self.parser.feed(data):
            self.counters.frames_received += 1
            if self._on_frame is not None:
                self._on_frame(frame)
        self.counters.bad_bytes_received += self.parser.garbage_bytes - before

    def _lost_while_idle(self, exc: BaseException) -> None:
        """The reader saw the port die: tell the writer task to reconnect now."""
        self._lost = exc
        self._wake.set()

    def _stop_reader(self, port: serial.SerialBase) -> None:
        fd = _fileno(port)
        if fd is not None:
            with contextlib.suppress(Exception):
                asyncio.get_running_loop().remove_reader(fd)

    async def _close_port(self) -> None:
        port, self._port = self._port, None
        if port is None:
            return
        self._stop_reader(port)
        with contextlib.suppress(Exception):
            await asyncio.to_thread(port.close)

    async def _final_stop(self) -> None:
        """STOP twice before the port closes, whatever state the writer was in."""
        port = self._port
        if port is None:
            _log.warning("final_stop_impossible", port=self.config.port, reason="port is down")
            return
        data = encode(STOP, protocol=self.protocol, address=self.config.address)
        spacing = frame_time(len(data), self.config) + self.config.min_gap_s
        # paced in real time: a virtual clock is no longer advanced by anyone at this point
        first_wait = min(spacing, max(0.0, self._line_free_at - self._clock.now()))
        try:
            async with asyncio.timeout(CLOSE_DRAIN_S):
                for wait in (first_wait, spacing):
                    await asyncio.sleep(wait)
                    await self._write_all(port, data)
                    self.counters.frames_sent += 1
                    self.counters.bytes_sent += len(data)
            self._wire_motion = STOP
        except (serial.SerialException, OSError, TimeoutError) as exc:
            _log.warning("final_stop_failed", port=self.config.port, error=str(exc))
        except asyncio.CancelledError:
            # cancelled again while closing: one last try without waiting, then give up
            with contextlib.suppress(Exception):
                port.write(data)
            raise


def _fileno(port: Any) -> int | None:
    try:
        fd = port.fileno()
    except (AttributeError, NotImplementedError, OSError, serial.SerialException):
        return None
    return fd if isinstance(fd, int) and fd >= 0 else None


async def _writable(fd: int) -> None:
    """Wait (event-driven) until `fd` accepts more bytes."""
    loop = asyncio.get_running_loop()
    future: asyncio.Future[None] = loop.create_future()

    def ready() -> None:
        if not future.done():
            future.set_result(None)

    loop.add_writer(fd, ready)
    try:
        await future
    finally:
        loop.remove_writer(fd)
