"""sd_notify against a real unix datagram socket: READY, STATUS, WATCHDOG cadence, STOPPING."""

from __future__ import annotations

import asyncio
import contextlib
import os
import socket
import uuid
from collections.abc import Iterator
from pathlib import Path

import pytest

from ptzd.sdnotify import Heartbeats, Notifier, Watchdog, watchdog_interval


class ManualClock:
    def __init__(self) -> None:
        self.t = 0.0

    def now(self) -> float:
        return self.t

    async def sleep(self, seconds: float) -> None:
        await asyncio.sleep(max(0.0, seconds))


@pytest.fixture
def notify_socket(tmp_path: Path) -> Iterator[tuple[socket.socket, str]]:
    path = tmp_path / "notify.sock"
    sock = socket.socket(socket.AF_UNIX, socket.SOCK_DGRAM)
    sock.bind(str(path))
    sock.settimeout(2.0)
    try:
        yield sock, str(path)
    finally:
        sock.close()


def drain(sock: socket.socket) -> list[str]:
    out: list[str] = []
    sock.setblocking(False)
    with contextlib.suppress(BlockingIOError):
        while True:
            out.append(sock.recv(4096).decode())
    sock.settimeout(2.0)
    return out


def test_ready_status_stopping_over_a_path_socket(notify_socket: tuple[socket.socket, str]) -> None:
    sock, path = notify_socket
    notifier = Notifier.from_environ({"NOTIFY_SOCKET": path})
    assert notifier.enabled
    assert notifier.ready(status="tracking cam1")
    assert sock.recv(4096) == b"READY=1\nSTATUS=tracking cam1"
    assert notifier.status("searching\nline two")
    assert sock.recv(4096) == b"STATUS=searching line two"
    assert notifier.watchdog()
    assert sock.recv(4096) == b"WATCHDOG=1"
    assert notifier.stopping()
    assert sock.recv(4096) == b"STOPPING=1"
    assert notifier.sent == 4
    notifier.close()


def test_abstract_namespace_socket() -> None:
    name = f"ptzd-test-{uuid.uuid4().hex}"
    sock = socket.socket(socket.AF_UNIX, socket.SOCK_DGRAM)
    sock.bind("\0" + name)
    sock.settimeout(2.0)
    try:
        notifier = Notifier.from_environ({"NOTIFY_SOCKET": "@" + name})
        assert notifier.ready()
        assert sock.recv(4096) == b"READY=1"
    finally:
        sock.close()


def test_outside_systemd_is_a_quiet_no_op() -> None:
    notifier = Notifier.from_environ({})
    assert not notifier.enabled
    assert notifier.ready() is False
    assert notifier.sent == 0


def test_vanished_socket_is_logged_not_raised(tmp_path: Path) -> None:
    notifier = Notifier(str(tmp_path / "gone.sock"))
    assert notifier.watchdog() is False
    assert notifier.failed == 1


def test_watchdog_from_environ(notify_socket: tuple[socket.socket, str]) -> None:
    _, path = notify_socket
    env = {"NOTIFY_SOCKET": path, "WATCHDOG_USEC": "30000000"}
    dog = Watchdog.from_environ(Notifier.from_environ(env), lambda: True, environ=env)
    assert dog is not None and dog.interval_s == 15.0
    assert Watchdog.from_environ(Notifier.from_environ(env), lambda: True, environ={}) is None
    assert Watchdog.from_environ(Notifier(None), lambda: True, environ=env) is None


def test_watchdog_interval_from_environment() -> None:
    assert watchdog_interval({"WATCHDOG_USEC": "20000000"}) == 10.0
    assert watchdog_interval({"WATCHDOG_USEC": "20000000", "WATCHDOG_PID": str(os.getpid())}) == 10
    assert watchdog_interval({"WATCHDOG_USEC": "20000000", "WATCHDOG_PID": "1"}) is None
    assert watchdog_interval({"WATCHDOG_USEC": "0"}) is None
    assert watchdog_interval({"WATCHDOG_USEC": "x"}) is None
    assert watchdog_interval({}) is None


async def test_watchdog_cadence_and_withheld_when_unhealthy(
    notify_socket: tuple[socket.socket, str],
) -> None:
    sock, path = notify_socket
    interval = watchdog_interval({"WATCHDOG_USEC": "100000"})  # 0.1 s -> ping every 0.05 s
    assert interval == 0.05
    healthy = True
    dog = Watchdog(Notifier(path), interval, lambda: healthy)
    task = asyncio.create_task(dog.run())
    try:
        await asyncio.sleep(0.5)
        pings = drain(sock)
        assert all(p == "WATCHDOG=1" for p in pings)
        assert 6 <= len(pings) <= 12, len(pings)  # ~10 at 20 Hz, allowing a busy machine

        healthy = False  # frames stopped: systemd must be allowed to notice
        await asyncio.sleep(0.06)
        drain(sock)
        await asyncio.sleep(0.4)
        assert drain(sock) == []
        assert dog.skipped >= 6

        healthy = True
        await asyncio.sleep(0.2)
        assert len(drain(sock)) >= 2
    finally:
        task.cancel()
        with contextlib.suppress(asyncio.CancelledError):
            await task


async def test_heartbeats_drive_the_watchdog(notify_socket: tuple[socket.socket, str]) -> None:
    sock, path = notify_socket
    clock = ManualClock()
    beats = Heartbeats(("frame", "control"), clock=clock)
    assert not beats.fresh(1.0)  # nothing seen yet: not healthy
    assert beats.stale(1.0) == ["frame", "control"]
    beats.beat("frame")
    beats.beat("control")
    assert beats.fresh(1.0)
    clock.t = 0.9
    beats.beat("control")
    clock.t = 1.5
    assert beats.stale(1.0) == ["frame"]  # frames stopped, control still ticking
    with pytest.raises(KeyError):
        beats.beat("bogus")

    dog = Watchdog(Notifier(path), 0.02, lambda: beats.fresh(1.0))
    task = asyncio.create_task(dog.run())
    try:
        await asyncio.sleep(0.15)
        assert drain(sock) == []
        beats.beat("frame")
        beats.beat("control")
        got = await asyncio.wait_for(asyncio.to_thread(sock.recv, 4096), 2.0)
        assert got == b"WATCHDOG=1"
    finally:
        task.cancel()
        with contextlib.suppress(asyncio.CancelledError):
            await task
