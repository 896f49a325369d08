"""systemd notify from the real daemon over a real unix datagram socket: READY after the
first frame, STATUS, WATCHDOG only while frames and control ticks are fresh, STOPPING on
shutdown; and `ptzd run` honouring the config's [logging] and [camera].name."""

from __future__ import annotations

import asyncio
import contextlib
import json
import os
import signal
import socket
import subprocess
import sys
import time
from collections.abc import AsyncIterator, Iterator
from dataclasses import dataclass
from pathlib import Path

from ptzd.app import Daemon
from ptzd.capture import FrameItem, VideoCaptureSource
from ptzd.clock import RealClock
from ptzd.pelco.link import PelcoLink
from ptzd.sdnotify import Notifier
from ptzd.vision.tracking import make_tracker
from tests.test_app import BOX, config, pty_pair, read_motions
from tests.test_app_capture import write_video


@dataclass
class Datagram:
    fields: dict[str, str]
    at: float  # monotonic time received
    frames_captured: int  # the daemon's count when it arrived


@contextlib.contextmanager
def notify_socket(directory: Path) -> Iterator[tuple[socket.socket, str]]:
    path = directory / "notify.sock"
    sock = socket.socket(socket.AF_UNIX, socket.SOCK_DGRAM)
    sock.bind(str(path))
    try:
        yield sock, str(path)
    finally:
        sock.close()


def parse(datagram: bytes) -> dict[str, str]:
    return dict(line.split("=", 1) for line in datagram.decode().splitlines())


class StallingSource:
    """A real video file, decoded and paced, whose first frame comes after `delay_s` and which
    then delivers `frames` frames and hangs (a camera that stops sending)."""

    def __init__(self, path: Path, clock: RealClock, *, frames: int, delay_s: float) -> None:
        self.inner = VideoCaptureSource(str(path), clock)
        self.count, self.delay_s = frames, delay_s
        self.stalled = asyncio.Event()

    async def frames(self) -> AsyncIterator[FrameItem]:
        await asyncio.sleep(self.delay_s)
        sent = 0
        async for item in self.inner.frames():
            yield item
            sent += 1
            if sent == self.count:
                self.stalled.set()
                await asyncio.Event().wait()  # hangs until cancelled


async def test_ready_after_first_frame_watchdog_only_while_fresh_stopping_on_stop(
    tmp_path: Path,
) -> None:
    video = tmp_path / "walk.avi"
    write_video(video, frames=200, fps=20.0)
    clock = RealClock()
    loop = asyncio.get_running_loop()
    received: list[Datagram] = []
    daemon: Daemon | None = None

    with notify_socket(tmp_path) as (sock, path), pty_pair() as (master, port):
        sock.setblocking(False)

        def on_datagram() -> None:
            with contextlib.suppress(BlockingIOError):
                while True:
                    data = sock.recv(4096)
                    count = daemon.stats.frames_captured if daemon is not None else -1
                    received.append(Datagram(parse(data), time.monotonic(), count))

        loop.add_reader(sock.fileno(), on_datagram)
        cfg = config(port)
        source = StallingSource(video, clock, frames=30, delay_s=0.5)
        try:
            async with PelcoLink(cfg.serial, clock=clock) as link:
                daemon = Daemon(
                    cfg,
                    source=source,
                    tracker_factory=lambda: make_tracker(cfg.tracker),
                    link=link,
                    clock=clock,
                    initial_box=BOX,
                    notifier=Notifier.from_environ({"NOTIFY_SOCKET": path}),
                    watchdog_environ={"WATCHDOG_USEC": "100000"},  # ping every 50 ms
                    health_max_age_s=0.4,
                    status_interval_s=0.2,
                )
                task = asyncio.create_task(daemon.run())
                await asyncio.wait_for(source.stalled.wait(), 20)
                stalled_at = time.monotonic()
                await asyncio.sleep(1.5)  # frames stale for > 1 s
                daemon.request_stop()
                await asyncio.wait_for(task, 10)
            await asyncio.sleep(0.05)
            on_datagram()
        finally:
            loop.remove_reader(sock.fileno())
        motions = read_motions(master)

    readies = [d for d in received if d.fields.get("READY") == "1"]
    assert len(readies) == 1
    ready = readies[0]
    assert ready.frames_captured >= 1  # sent after the first frame, not before
    before_ready = received[: received.index(ready)]
    assert not any("WATCHDOG" in d.fields for d in before_ready)  # no frames yet: unhealthy

    pings = [d.at for d in received if d.fields.get("WATCHDOG") == "1"]
    healthy_pings = [t for t in pings if ready.at <= t <= stalled_at]
    assert len(healthy_pings) >= 10  # 30 frames at 20 fps = 1.5 s of health at 50 ms
    # frames stopped: pings stop once the last frame is older than 0.4 s (+ one interval)
    assert not [t for t in pings if t > stalled_at + 0.4 + 0.15]

    statuses = [d.fields["STATUS"] for d in received if "STATUS" in d.fields and not
                {"READY", "STOPPING"} & d.fields.keys()]  # fmt: skip
    assert any("tracking" in s and "fps" in s and "dropped" in s for s in statuses)
    assert any("stalled: frame" in s for s in statuses)  # the stall shows in systemctl status

    stopping = [i for i, d in enumerate(received) if d.fields.get("STOPPING") == "1"]
    assert len(stopping) == 1
    assert stopping[0] > received.index(ready)
    assert motions[0].is_stop and motions[-1].is_stop


def test_ptzd_run_under_systemd_notify_and_config_logging(tmp_path: Path) -> None:
    """`ptzd run` as systemd would start it: READY, WATCHDOG, STOPPING on SIGTERM, exit 0;
    JSON log lines carry the camera name and level from the config."""
    video = tmp_path / "walk.avi"
    write_video(video, frames=400, fps=20.0)
    master, slave = os.openpty()
    os.set_blocking(master, False)
    cfg = tmp_path / "gate.toml"
    cfg.write_text(
        f'[camera]\nname = "gate-7"\n[logging]\nlevel = "info"\nformat = "json"\n'
        f'[capture]\nsource = "{video}"\n[serial]\nport = "{os.ttyname(slave)}"\n'
    )
    with notify_socket(tmp_path) as (sock, path):
        sock.settimeout(15.0)
        env = {**os.environ, "NOTIFY_SOCKET": path, "WATCHDOG_USEC": "200000"}
        env.pop("WATCHDOG_PID", None)
        env.pop("JOURNAL_STREAM", None)
        proc = subprocess.Popen(
            [sys.executable, "-m", "ptzd", "run", "--config", str(cfg), "--init", "150,90,20,60"],
            stdout=subprocess.PIPE,
            stderr=subprocess.PIPE,
            env=env,
        )
        try:
            received = [parse(sock.recv(4096))]
            while sum(1 for f in received if f.get("WATCHDOG") == "1") < 3:
                received.append(parse(sock.recv(4096)))
            proc.send_signal(signal.SIGTERM)
            _, stderr = proc.communicate(timeout=20)
            sock.settimeout(0.5)
            with contextlib.suppress(TimeoutError):
                while True:
                    received.append(parse(sock.recv(4096)))
        finally:
            if proc.poll() is None:
                proc.kill()
            os.close(master)
            os.close(slave)
    assert proc.returncode == 0, stderr.decode()
    assert received[0].get("READY") == "1"  # nothing before it: READY comes first
    assert received[-1].get("STOPPING") == "1"
    events = [json.loads(line) for line in stderr.decode().splitlines() if line.startswith("{")]
    assert events, stderr.decode()
    assert all(e["camera"] == "gate-7" for e in events)
    assert {"ready", "daemon_stopped"} <= {e["event"] for e in events}
