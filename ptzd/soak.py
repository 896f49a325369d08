"""Soak harness: the real daemon, the simulated dome and a real broker, for a long time.

`ptzd soak --minutes N --report DIR [--faults day-night,serial-reset,stream-stall,broker-restart]`:

- `ptzd sim-camera` runs as its own process (MJPEG over HTTP, Pelco over TCP);
- `ptzd run` runs as another process with a real config file, its serial port going through
  a TCP proxy here (which counts every Pelco command and can reset the line), the harness
  acting as systemd (`NOTIFY_SOCKET`, `WATCHDOG_USEC`) to read STATUS= and watchdog pings;
- a real mosquitto, watched by an MQTT subscriber that counts messages.

Inside the daemon process a probe thread (`python -m ptzd.soak probe ...`, which then runs
the ordinary `ptzd` CLI) measures event-loop lag and the asyncio task count; RSS and open fds
come from /proc. Everything is written to `DIR/report.json` plus `DIR/soak.png`.

`--virtual-clock` runs the in-process closed loop (`ptzd sim --virtual-clock`) for N
simulated minutes as fast as it goes, with the same probe and /proc sampling (no faults:
there is no separate process to break) and the same leak checks (`virtual_report`);
`--fps` streams the simulated dome at a lower rate (`[sim] fps`) for day-long runs.

Faults, each with its expected recovery (checked, see docs/reliability.md):
- `serial-reset`: every proxied serial connection is reset (TCP RST) and the port refuses
  connections for 2 s. Expect a reconnect whose first two commands are STOP, STOP.
- `stream-stall`: the sim-camera's MJPEG stream stops for 6 s (SIGUSR1, SIGUSR2 resumes
  it) while its dome goes on taking commands, as a real dome's controller does when its
  video stalls. Expect a STOP on the wire within `max_track_age_s` + 1 s, the watchdog to
  stop being fed, and frames to resume. (Until 2026-12-03 the whole process was frozen with
  SIGSTOP; that froze the dome's serial line too, and on SIGCONT the simulated dome applied
  6 s of its last speed at once: a dome thrown 56 deg off, staring at the ground.)
- `broker-restart`: mosquitto is killed (SIGKILL) and restarted 2 s later on the same port.
  Expect `availability` = `online` (retained) to be republished.
- `day-night`: the sim-camera's dome goes to night mode (grey views, its IR-cut filter out;
  `ptzd.sim.cli.DUSK_SIGNAL`) for 15 s, then back (`DAWN_SIGNAL`); an operator selects a
  walker after each (each change waits up to 20 s for someone whole in view). Expect the
  daemon's tracker (`[tracker] kind = "auto"`) to switch to its night kind within 15 s of
  dusk (at once for a tracked target, else at the next lock) and back to its day kind
  within 15 s of dawn, both in its log (`tracker_switched`) and in the `tracker` field of
  its MQTT `track` messages, and frames to keep coming.
"""

from __future__ import annotations

import asyncio
import contextlib
import functools
import json
import os
import re
import shutil
import signal
import socket
import statistics
import struct
import sys
import threading
import time
from collections.abc import Callable, Iterable, Mapping, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import IO, Any

from ptzd.closed_loop import fully_visible, in_central_cell
from ptzd.errors import UsageError
from ptzd.heap import malloc_stats
from ptzd.pelco.codec import FrameParser, Motion, PelcoProtocol, Preset, PresetAction, encode
from ptzd.pelco.config import SerialConfig
from ptzd.sim.groundtruth import GroundTruth
from ptzd.sim.sources import open_wide_source

# in this order in the CI soak: day-night first, so that its one-time step in memory comes
# before the warm-up ends
FAULTS = ("day-night", "serial-reset", "stream-stall", "broker-restart")
STALL_S = 6.0
NIGHT_S = 15.0  # `day-night`: how long the night lasts, and how long each switch may take
# `day-night`: the longest each change of light waits for someone in view (the CI soak's
# later faults are due 36 s apart)
LIGHT_WAIT_S = 20.0
STOP_WITHIN_S = 1.5  # max_track_age_s (0.5) + a control tick + the wire
OUTAGE_S = 2.0
WATCHDOG_USEC = 10_000_000  # pings every 5 s, as the shipped unit's WatchdogSec=10
CAMERA = "soak"
HOME_PRESET = 1  # the dome's start pose, stored before the daemon starts
INIT_BOX = "290,170,60,140"  # until the first MQTT select: whatever is in the view centre
RESELECT_S = 60.0
RETRY_SELECT_S = 2.0  # no walker fit to select: look again this soon
SCENE = "synthetic:0"
_STATUS = re.compile(r"frames (\d+), dropped (\d+)")


@dataclass(frozen=True)
class SoakOptions:
    minutes: float
    report_dir: Path
    faults: tuple[str, ...] = ()
    virtual_clock: bool = False
    sample_s: float = 2.0
    warmup_s: float = 30.0
    fps: float | None = None  # the simulated dome's frame rate (`[sim] fps`); None: the scene's
    max_heap_growth_mb: float = 5.0  # the leak check's limit on anonymous RSS growth

    def __post_init__(self) -> None:
        if not self.minutes > 0:
            raise UsageError(f"--minutes must be > 0; got {self.minutes}")
        if not self.max_heap_growth_mb > 0:
            raise UsageError(f"--max-heap-growth-mb must be > 0; got {self.max_heap_growth_mb}")
        if self.fps is not None and not 0 < self.fps <= 240:
            raise UsageError(f"--fps must be in (0, 240]; got {self.fps}")
        if self.fps is not None and not self.virtual_clock:
            raise UsageError("--fps needs --virtual-clock (the real-time soak streams at 25 fps)")
        unknown = [f for f in self.faults if f not in FAULTS]
        if unknown:
            raise UsageError(f"unknown fault(s) {unknown}; choose from {', '.join(FAULTS)}")
        if self.virtual_clock and self.faults:
            raise UsageError("--faults need the real-time soak (no --virtual-clock)")


# --- the probe, inside the measured process ------------------------------------------------


def _probe_loop(loop: asyncio.AbstractEventLoop, path: Path, interval: float) -> None:
    """Every `interval` s: schedule a callback on `loop` and time how late it runs (lag);
    the callback counts the loop's tasks. One JSON line per sample."""
    with path.open("a", encoding="utf-8") as out:
        while not loop.is_closed():
            time.sleep(interval)
            sample: dict[str, float] = {}
            done = threading.Event()
            asked = time.monotonic()

            def measure(
                asked: float = asked,
                sample: dict[str, float] = sample,
                done: threading.Event = done,
            ) -> None:
                sample["lag_s"] = time.monotonic() - asked
                tasks = len(asyncio.all_tasks(loop))
                # zero tasks: the callback ran as `asyncio.run` wound down, between the main
                # task's end and the loop's close; that is no count of the daemon's tasks
                if tasks:
                    sample["tasks"] = tasks
                done.set()

            try:
                loop.call_soon_threadsafe(measure)
            except RuntimeError:  # the loop closed between the check and the call
                return
            if not done.wait(timeout=30.0):
                sample = {"lag_s": time.monotonic() - asked}
            sample["t"] = time.monotonic()
            sample["threads"] = threading.active_count()
            sample.update(malloc_stats())
            out.write(json.dumps(sample) + "\n")
            out.flush()


def run_probed(path: Path, interval: float, argv: Sequence[str]) -> int:
    """Run the `ptzd` CLI with `argv`, probing every event loop it creates."""

    class ProbePolicy(asyncio.DefaultEventLoopPolicy):
        def new_event_loop(self) -> asyncio.AbstractEventLoop:
            loop = super().new_event_loop()
            threading.Thread(
                target=_probe_loop, args=(loop, path, interval), name="soak-probe", daemon=True
            ).start()
            return loop

    asyncio.set_event_loop_policy(ProbePolicy())
    from ptzd.cli import main

    return main(list(argv))


# --- the parts around the daemon -----------------------------------------------------------


async def _install_home_preset(host: str, port: int) -> None:
    """Store the sim-camera dome's start pose (the scene's middle, fully zoomed out) as
    preset `HOME_PRESET`, as an installer does from his keyboard before the daemon runs,
    for the daemon's `[control.lost] home_preset`. Without a home the dome stays wherever
    the last target led it: in a CI soak the night's walker led it to pan 84 deg, off the
    scene's side, and it looked at nobody for the last two minutes of the run."""
    serial = SerialConfig()  # the soak's daemon speaks the default protocol and address
    command = encode(
        Preset(PresetAction.SET, HOME_PRESET),
        protocol=PelcoProtocol(serial.protocol),
        address=serial.address,
    )
    _, writer = await asyncio.open_connection(host, port)
    try:
        writer.write(command)
        await writer.drain()
    finally:
        writer.close()
        await writer.wait_closed()


def _free_port() -> int:
    with socket.socket() as sock:
        sock.bind(("127.0.0.1", 0))
        port: int = sock.getsockname()[1]
        return port


class Mosquitto:
    """A local mosquitto on a fixed port, startable again after a kill."""

    def __init__(self, workdir: Path) -> None:
        binary = shutil.which("mosquitto") or "/usr/sbin/mosquitto"
        if not Path(binary).exists():
            raise UsageError("mosquitto not found (scripts/system-deps.sh installs it)")
        self.binary = binary
        self.port = _free_port()
        self.conf = workdir / "mosquitto.conf"
        self.log = workdir / "mosquitto.log"
        self.process: asyncio.subprocess.Process | None = None

    async def start(self) -> None:
        import getpass

        self.conf.write_text(
            f"user {getpass.getuser()}\nlistener {self.port} 127.0.0.1\n"
            "allow_anonymous true\npersistence false\nlog_dest stderr\n"
        )
        with self.log.open("ab") as log:
            self.process = await asyncio.create_subprocess_exec(
                self.binary, "-c", str(self.conf), stdout=log, stderr=log
            )
        async with asyncio.timeout(10):  # ready when the port accepts connections
            while True:
                with contextlib.suppress(OSError):
                    _, writer = await asyncio.open_connection("127.0.0.1", self.port)
                    writer.close()
                    return
                await asyncio.sleep(0.05)

    async def kill(self) -> None:
        if self.process is not None and self.process.returncode is None:
            self.process.kill()
            await self.process.wait()

    async def stop(self) -> None:
        if self.process is not None and self.process.returncode is None:
            self.process.terminate()
            await self.process.wait()


@dataclass
class _Connection:
    opened: float
    writer: asyncio.StreamWriter
    first_commands: list[Motion | str] = field(default_factory=list)


class SerialProxy:
    """TCP proxy between the daemon's `socket://` port and the simulated dome.

    Counts every Pelco frame the daemon sends, remembers the first commands of each
    connection (STOP, STOP after a reconnect) and can reset the line (TCP RST)."""

    def __init__(self, upstream: tuple[str, int], now: Callable[[], float]) -> None:
        self.upstream = upstream
        self.now = now
        self.port = 0
        self.server: asyncio.Server | None = None
        self.connections: list[_Connection] = []
        self.commands = 0
        self.stops = 0
        self.last_motion: Motion | None = None
        self.stop_times: list[float] = []
        self._live: list[asyncio.StreamWriter] = []

    async def start(self) -> None:
        self.server = await asyncio.start_server(self._client, "127.0.0.1", self.port)
        self.port = self.server.sockets[0].getsockname()[1]

    async def _client(self, reader: asyncio.StreamReader, writer: asyncio.StreamWriter) -> None:
        try:
            up_reader, up_writer = await asyncio.open_connection(*self.upstream)
        except OSError:
            writer.close()
            return
        conn = _Connection(self.now(), writer)
        self.connections.append(conn)
        self._live += [writer, up_writer]
        parser = FrameParser()

        async def downstream() -> None:  # dome replies -> daemon
            with contextlib.suppress(ConnectionError, OSError):
                while data := await up_reader.read(4096):
                    writer.write(data)
                    await writer.drain()

        back = asyncio.create_task(downstream())
        try:
            with contextlib.suppress(ConnectionError, OSError):
                while data := await reader.read(4096):
                    for frame in parser.feed(data):
                        self._count(conn, frame.command)
                    up_writer.write(data)
                    await up_writer.drain()
        finally:
            back.cancel()
            for w in (writer, up_writer):
                with contextlib.suppress(Exception):
                    w.close()
                with contextlib.suppress(ValueError):
                    self._live.remove(w)

    def _count(self, conn: _Connection, command: object) -> None:
        self.commands += 1
        name: Motion | str = command if isinstance(command, Motion) else type(command).__name__
        if len(conn.first_commands) < 3:
            conn.first_commands.append(name)
        if isinstance(command, Motion):
            self.last_motion = command
            if command.is_stop:
                self.stops += 1
                self.stop_times.append(self.now())

    async def reset(self, outage_s: float) -> None:
        """RST every connection and refuse new ones for `outage_s`."""
        assert self.server is not None
        self.server.close()
        for writer in list(self._live):
            sock = writer.get_extra_info("socket")
            if sock is not None:
                with contextlib.suppress(OSError):
                    sock.setsockopt(socket.SOL_SOCKET, socket.SO_LINGER, struct.pack("ii", 1, 0))
            writer.transport.abort()
        await asyncio.sleep(outage_s)
        await self.start()

    async def close(self) -> None:
        if self.server is not None:
            self.server.close()
        for writer in list(self._live):
            writer.transport.abort()


class MqttWatcher:
    """Counts every message under the camera's topics; notes when `online` is (re)published
    and when the `track` messages start naming another tracker."""

    def __init__(self, port: int, now: Callable[[], float]) -> None:
        self.port = port
        self.now = now
        self.messages = 0
        self.online_times: list[float] = []
        self.connects = 0
        self.tracker_changes: list[tuple[float, str]] = []  # (time, the tracker named from then)

    async def run(self) -> None:
        import aiomqtt

        while True:
            try:
                async with aiomqtt.Client("127.0.0.1", self.port, timeout=5) as client:
                    self.connects += 1
                    await client.subscribe(f"ptzd/{CAMERA}/#")
                    async for message in client.messages:
                        self.messages += 1
                        topic = str(message.topic)
                        if topic.endswith("/availability") and message.payload == b"online":
                            self.online_times.append(self.now())
                        elif topic.endswith("/track"):
                            self._note_tracker(message.payload)
            except aiomqtt.MqttError:
                await asyncio.sleep(0.5)

    def _note_tracker(self, payload: object) -> None:
        if not isinstance(payload, bytes | bytearray):
            return
        with contextlib.suppress(ValueError, AttributeError):
            kind = json.loads(payload).get("tracker")
            known = self.tracker_changes[-1][1] if self.tracker_changes else None
            if isinstance(kind, str) and kind != known:
                self.tracker_changes.append((self.now(), kind))

    def named_after(self, since: float, kind: str) -> float | None:
        """When the `track` messages went over to naming `kind` after `since`, or None."""
        return next((t for t, k in self.tracker_changes if t > since and k == kind), None)


class NotifySocket:
    """The systemd side of sd_notify: STATUS= lines and WATCHDOG=1 pings, timestamped."""

    def __init__(self, path: Path, now: Callable[[], float]) -> None:
        self.path = path
        self.now = now
        self.sock = socket.socket(socket.AF_UNIX, socket.SOCK_DGRAM)
        self.sock.setblocking(False)
        self.pings: list[float] = []
        self.frames = 0
        self.dropped = 0
        self.frame_times: list[tuple[float, int]] = []
        self.ready = False

    def open(self) -> None:
        self.path.unlink(missing_ok=True)
        self.sock.bind(str(self.path))

    async def run(self) -> None:
        loop = asyncio.get_running_loop()
        while True:
            data = await loop.sock_recv(self.sock, 65536)
            for line in data.decode(errors="replace").splitlines():
                key, _, value = line.partition("=")
                if key == "WATCHDOG" and value == "1":
                    self.pings.append(self.now())
                elif key == "READY":
                    self.ready = True
                elif key == "STATUS" and (match := _STATUS.search(value)):
                    self.frames, self.dropped = int(match.group(1)), int(match.group(2))
                    self.frame_times.append((self.now(), self.frames))

    def close(self) -> None:
        self.sock.close()
        self.path.unlink(missing_ok=True)


def proc_sample(pid: int) -> dict[str, float]:
    """RSS (MB), its anonymous part (the heap, where a leak would show; the rest is pages
    of mapped files such as the libraries), open file descriptors, and the OS threads (the
    probe's `threads` counts Python's; FFmpeg's and OpenCV's are native), from /proc."""
    rss_kb = anon_kb = 0
    os_threads = -1
    with contextlib.suppress(OSError):
        for line in Path(f"/proc/{pid}/status").read_text().splitlines():
            if line.startswith("VmRSS:"):
                rss_kb = int(line.split()[1])
            elif line.startswith("RssAnon:"):
                anon_kb = int(line.split()[1])
            elif line.startswith("Threads:"):
                os_threads = int(line.split()[1])
    try:
        fds = sum(1 for _ in Path(f"/proc/{pid}/fd").iterdir())
    except OSError:
        fds = -1
    return {
        "rss_mb": rss_kb / 1024,
        "rss_anon_mb": anon_kb / 1024,
        "fds": fds,
        "os_threads": os_threads,
    }


def _last_probe(path: Path) -> dict[str, Any]:
    with contextlib.suppress(OSError, ValueError, IndexError):
        lines = path.read_text().splitlines()
        last: dict[str, Any] = json.loads(lines[-1])
        return last
    return {}


def _switched_to(log: Path, offset: int, kind: str) -> bool:
    """Whether the daemon's JSON log, from byte `offset` on, says its tracker switched to
    `kind` (the `tracker_switched` event of ptzd/vision/auto.py)."""
    with log.open("rb") as f:
        f.seek(offset)
        text = f.read().decode(errors="replace")
    for line in text.splitlines():
        if '"tracker_switched"' not in line:
            continue
        with contextlib.suppress(ValueError):
            event = json.loads(line[line.index("{") :])
            if event.get("event") == "tracker_switched" and event.get("kind") == kind:
                return True
    return False


def _last_json_lines(path: Path, count: int) -> list[dict[str, Any]]:
    """The last `count` complete JSON lines (oldest first) of a file another process is
    appending to (fewer if it has fewer)."""
    found: list[dict[str, Any]] = []
    with contextlib.suppress(OSError), path.open("rb") as f:
        f.seek(max(0, f.seek(0, os.SEEK_END) - 8192 * count))
        for raw in reversed(f.read().splitlines()):
            with contextlib.suppress(ValueError):
                found.append(json.loads(raw))
                if len(found) == count:
                    break
    return found[::-1]


def shown_record(
    records: Sequence[Mapping[str, Any]], latency_s: float
) -> Mapping[str, Any] | None:
    """Of the simulator's newest ground-truth records (oldest first), the one of the frame
    the daemon has when a command sent now arrives: the newest at least `latency_s` older
    than the newest record (the oldest given if none is that old); None if none."""
    if not records:
        return None
    newest = float(records[-1]["t"])
    shown = [r for r in records if float(r["t"]) <= newest - latency_s]
    return shown[-1] if shown else records[0]


def dome_still(poses: Sequence[Mapping[str, Any]], frames: int) -> bool:
    """Whether the last `frames` rendered frames (camera.jsonl records) share one pose."""
    if len(poses) < frames:
        return False
    keys = ("pan", "tilt", "hfov")
    first = tuple(poses[-frames][k] for k in keys)
    return all(tuple(p[k] for k in keys) == first for p in poses[-frames:])


def _probe_lags(path: Path) -> list[float]:
    with contextlib.suppress(OSError):
        return [json.loads(line)["lag_s"] for line in path.read_text().splitlines() if line]
    return []


async def _spawn(argv: Sequence[str], log: IO[bytes], **kw: Any) -> asyncio.subprocess.Process:
    return await asyncio.create_subprocess_exec(
        *argv, stdout=asyncio.subprocess.PIPE, stderr=log, **kw
    )


async def _announced(
    process: asyncio.subprocess.Process, prefixes: tuple[str, ...]
) -> dict[str, str]:
    """Read `prefix value` lines from a child's stdout until every prefix was seen."""
    assert process.stdout is not None
    found: dict[str, str] = {}
    async with asyncio.timeout(30):
        while len(found) < len(prefixes):
            raw = await process.stdout.readline()
            if not raw:
                raise RuntimeError(f"child exited before announcing {prefixes}")
            word, _, value = raw.decode().strip().partition(" ")
            if word in prefixes:
                found[word] = value
    return found


async def _drain(stream: asyncio.StreamReader | None, sink: IO[bytes]) -> None:
    if stream is None:
        return
    while data := await stream.read(65536):
        sink.write(data)
        sink.flush()


def rss_summary(samples: Sequence[Mapping[str, Any]]) -> dict[str, float | None]:
    """The report's memory fields from the samples after warm-up (see `rss_trend`): RSS and
    its anonymous part, `RssAnon`.

    The leak check is on the anonymous part (heap, arenas, numpy buffers): that is where
    a leak shows. The rest of RSS is pages of the mapped libraries, which the kernel maps
    in as it pleases: the same daemon, same run, sat at 117 MB from a venv made days ago
    and at 162 MB from one just installed (cv2's library 12.7 vs 37.6 MB resident; the
    anonymous part 52.7 vs 51.9 MB), and those pages go on being mapped in while the run
    reaches code it had not run yet."""
    out: dict[str, float | None] = {}
    for key, name in (("rss_mb", "rss"), ("rss_anon_mb", "rss_anon")):
        trend = rss_trend([float(s[key]) for s in samples if s.get(key)])
        start, end = trend if trend is not None else (None, None)
        out[f"{name}_mb_after_warmup"] = None if start is None else round(start, 2)
        out[f"{name}_mb_end"] = None if end is None else round(end, 2)
        growth = None if start is None or end is None else round(end - start, 2)
        out[f"{name}_growth_mb"] = growth
    return out


def rss_trend(rss: Sequence[float]) -> tuple[float, float] | None:
    """(start, end) RSS of the samples after warm-up: the medians of their first and their
    last quarter. A leak is a trend; the heap breathes by a few MB from one sample to the
    next (a CI soak went 117 -> 124 -> 119.6 -> 122.6 MB in its last minute), so one sample
    at each end would fail a steady daemon at random."""
    if not rss:
        return None
    quarter = max(1, len(rss) // 4)
    return statistics.median(rss[:quarter]), statistics.median(rss[-quarter:])


def _percentile(values: Sequence[float], q: float) -> float | None:
    if not values:
        return None
    ordered = sorted(values)
    return ordered[min(len(ordered) - 1, int(q * (len(ordered) - 1) + 0.5))]


# command -> first frame showing it, through sim-camera's TCP serial, its renderer, MJPEG
# and FFmpeg: median of `python -m bench.frame_latency` (0.115-0.121 s on the 2-core box)
SIM_CAMERA_LATENCY_S = 0.12
STILL_FRAMES = 5  # the operator selects on a picture that has stood still this long
STILL_WAIT_S = 10.0
SHOWN_LOOKBACK = 10  # records read to find the one shown (0.4 s at 25 fps)
VIEW = (640, 480)  # the sim-camera's view size ([sim] defaults)
SETTLE_FRAMES = 75  # 3 s at the scene's 25 fps: the dome turns to a new selection first
MIN_REMAINING_FRAMES = SETTLE_FRAMES + 75  # a selection measures at least 3 s of centring


def selection_centring(
    lines: Iterable[str], selections: Sequence[Mapping[str, Any]], settle_frames: int
) -> dict[str, Any]:
    """How the daemon kept each operator-selected walker, from the simulator's ground truth
    (`groundtruth_view.jsonl` lines), as the closed-loop issue measures it: the share of
    frames with the walker's centre in the central cell of the 3x3 grid, and in view.

    Counted from `settle_frames` after each selection until the next selection, over the
    frames in which the walker is in the scene (one the dome lost sight of counts against
    it), and only until he first leaves it: a walker who has walked out of the wide image
    is nobody's to centre, and the one who walks in when the looping scene comes round
    again is not whom the operator picked (he is off-centre until someone selects him:
    in a 30-minute soak that took 0.14-0.30 off each of walker 19's eight selections)."""
    marks = sorted((int(s["frame"]), str(s["walker"])) for s in selections)
    per: dict[int, dict[str, Any]] = {}
    gone: set[int] = set()  # selections whose walker has left the scene
    errors_x: list[float] = []
    errors_y: list[float] = []
    for line in lines:
        try:
            record = json.loads(line)
            frame, boxes = int(record["frame"]), record["boxes"]
        except (ValueError, KeyError, TypeError):
            continue
        current = [(f, w) for f, w in marks if f <= frame]
        if not current:
            continue
        selected_at, walker = current[-1]
        if walker not in boxes:
            gone.add(selected_at)
            continue
        if frame < selected_at + settle_frames or selected_at in gone:
            continue
        entry = per.setdefault(
            selected_at, {"frame": selected_at, "walker": walker, "frames": 0, "in_view": 0,
                          "centred": 0}
        )  # fmt: skip
        entry["frames"] += 1
        box = boxes[walker]
        if box is None:
            continue
        entry["in_view"] += 1
        cx, cy = box[0] + box[2] / 2, box[1] + box[3] / 2
        errors_x.append(abs(cx - VIEW[0] / 2) / (VIEW[0] / 2))
        errors_y.append(abs(cy - VIEW[1] / 2) / (VIEW[1] / 2))
        entry["centred"] += in_central_cell(cx, cy, *VIEW)
    frames = sum(e["frames"] for e in per.values())
    for entry in per.values():
        n = max(1, entry["frames"])
        entry["in_view"] = round(entry["in_view"] / n, 3)
        entry["centred"] = round(entry["centred"] / n, 3)
    weighted = [(e["frames"], e["in_view"], e["centred"]) for e in per.values()]
    return {
        "frames": frames,
        "in_view": round(sum(n * v for n, v, _ in weighted) / frames, 3) if frames else None,
        "centred": round(sum(n * c for n, _, c in weighted) / frames, 3) if frames else None,
        "median_abs_ex": _round(statistics.median(errors_x), 3) if errors_x else None,
        "median_abs_ey": _round(statistics.median(errors_y), 3) if errors_y else None,
        "selections": list(per.values()),
    }


def operator_choice(
    record: Mapping[str, Any], truth: GroundTruth
) -> tuple[str, list[float]] | None:
    """Whom the soak's operator selects in a `groundtruth_view.jsonl` record: the walker with
    the biggest box well inside the view (centre at least an eighth of the view's width from
    its sides, 80..560 px of the 640, over 30 px tall, no edge on the view's border) that
    is fully visible in the wide scene (`truth`'s visibility at the record's video frame);
    None if nobody is.

    No edge on the border: the record's boxes are clipped to the view, and a walker close
    to the dome cut off by the bottom edge has the biggest box (a 5-minute soak selected
    three of five that way, e.g. 125 x 104 px of head and shoulders); an operator draws his
    box round a whole person.

    And only a walker who stays in the scene `MIN_REMAINING_FRAMES` more (`truth`'s track;
    one not in it counts as staying): centring is scored from 3 s after a selection until
    the walker leaves, so one about to leave gives no measure (a 5-minute soak spent three
    of five selections on walker 2 in his last 60 frames)."""
    wide_frame = int(record["video_frame"])  # already wrapped round the looping scene
    width, height = VIEW

    def stays(walker: str) -> bool:
        frames = truth.tracks.get(int(walker))
        return not frames or max(frames) - wide_frame >= MIN_REMAINING_FRAMES

    boxes = {
        walker: box
        for walker, box in record.get("boxes", {}).items()
        if box is not None
        and width / 8 < box[0] + box[2] / 2 < width * 7 / 8
        and box[3] > 30
        and box[0] > 0
        and box[1] > 0
        and box[0] + box[2] < width
        and box[1] + box[3] < height
        and fully_visible(truth, int(walker), wide_frame)
        and stays(walker)
    }
    if not boxes:
        return None
    return max(boxes.items(), key=lambda item: item[1][2] * item[1][3])


def _scene_truth() -> GroundTruth:
    """The soak scene's wide ground truth (boxes and visibility; a few seconds of CPU)."""
    gt = open_wide_source(SCENE).ground_truth
    if gt is None:  # a synthetic scene always has one
        raise UsageError(f"{SCENE}: no ground truth")
    return gt


# --- the real-time soak ---------------------------------------------------------------------


class Soak:
    def __init__(self, options: SoakOptions) -> None:
        self.options = options
        self.dir = options.report_dir
        self.t0 = time.monotonic()
        self.samples: list[dict[str, Any]] = []
        self.fault_log: list[dict[str, Any]] = []
        self.selections: list[dict[str, Any]] = []

    def now(self) -> float:
        return time.monotonic() - self.t0

    def _config_text(self, http_url: str, serial_port: int, mqtt_port: int) -> str:
        return (
            f'[camera]\nname = "{CAMERA}"\n[logging]\nformat = "json"\n'
            f'[capture]\nsource = "{http_url}"\nlatency_s = {SIM_CAMERA_LATENCY_S}\n'
            f'[serial]\nport = "socket://127.0.0.1:{serial_port}"\nreconnect_max_s = 1.0\n'
            f'[mqtt]\nenabled = true\nurl = "mqtt://127.0.0.1:{mqtt_port}"\n'
            "reconnect_max_s = 1.0\n"
            f"[control.lost]\nhome_preset = {HOME_PRESET}\n"
        )

    async def run(self) -> dict[str, Any]:
        opts = self.options
        self.dir.mkdir(parents=True, exist_ok=True)
        duration = opts.minutes * 60.0
        broker = Mosquitto(self.dir)
        await broker.start()
        py = sys.executable
        sim_log = (self.dir / "sim-camera.log").open("wb")
        daemon_log = (self.dir / "daemon.log").open("wb")
        tasks: list[asyncio.Task[None]] = []
        sim: asyncio.subprocess.Process | None = None
        daemon: asyncio.subprocess.Process | None = None
        proxy: SerialProxy | None = None
        notify = NotifySocket(Path(f"/tmp/ptzd-soak-{os.getpid()}.sock"), self.now)
        probe = self.dir / "probe.jsonl"
        probe.unlink(missing_ok=True)
        exit_code: int | None = None
        # the scene's wide ground truth, for whom the operator can see (visibility per frame),
        # worked out in a thread while the processes start
        truth_task = asyncio.create_task(asyncio.to_thread(_scene_truth))
        try:
            sim = await _spawn(
                [py, "-m", "ptzd", "--log-format", "json", "sim-camera", "--scene",
                 SCENE, "--serial", "tcp://127.0.0.1:0", "--http", "127.0.0.1:0",
                 "--loop", "--record", str(self.dir / "sim")],
                sim_log,
            )  # fmt: skip
            announced = await _announced(sim, ("serial", "http"))
            tasks.append(asyncio.create_task(_drain(sim.stdout, sim_log)))
            host, _, port = announced["serial"].removeprefix("socket://").rpartition(":")
            await _install_home_preset(host, int(port))
            proxy = SerialProxy((host, int(port)), self.now)
            await proxy.start()
            config = self.dir / "ptzd.toml"
            config.write_text(self._config_text(announced["http"], proxy.port, broker.port))
            config.chmod(0o600)
            notify.open()
            env = {
                **os.environ,
                "NOTIFY_SOCKET": str(notify.path),
                "WATCHDOG_USEC": str(WATCHDOG_USEC),
            }
            daemon = await asyncio.create_subprocess_exec(
                py, "-m", "ptzd.soak", "probe", str(probe), "1.0", "run", "--config",
                str(config), "--init", INIT_BOX,
                stdout=daemon_log, stderr=daemon_log, env=env,
            )  # fmt: skip
            watcher = MqttWatcher(broker.port, self.now)
            tasks += [
                asyncio.create_task(notify.run()),
                asyncio.create_task(watcher.run()),
            ]
            schedule = [
                ((i + 1) * duration / (len(opts.faults) + 1), name)
                for i, name in enumerate(opts.faults)
            ]
            await self._wait_for(lambda: notify.ready, 60)
            scene_truth = await truth_task
            next_sample = 0.0
            next_select = self.now()
            while self.now() < duration:
                if self.now() >= next_select:  # the scenario: follow a new walker each minute
                    if await self._select(broker.port, scene_truth):
                        next_select += RESELECT_S
                    else:
                        next_select = self.now() + RETRY_SELECT_S
                if daemon.returncode is not None:
                    break
                if schedule and self.now() >= schedule[0][0]:
                    _, name = schedule.pop(0)
                    await self._inject(name, proxy, sim, broker, notify, watcher, scene_truth)
                    continue
                if self.now() >= next_sample:
                    self._sample(daemon.pid, probe, proxy, notify, watcher)
                    next_sample += opts.sample_s
                await asyncio.sleep(0.2)
            if daemon.returncode is None:
                daemon.send_signal(signal.SIGTERM)
                async with asyncio.timeout(30):
                    exit_code = await daemon.wait()
            else:
                exit_code = daemon.returncode
            await asyncio.sleep(0.3)  # the last STOP reaches the proxy
        finally:
            truth_task.cancel()  # a no-op once it is done
            for task in tasks:
                task.cancel()
            for child in (daemon, sim):
                if child is not None and child.returncode is None:
                    with contextlib.suppress(ProcessLookupError):
                        child.terminate()
                    with contextlib.suppress(TimeoutError):
                        async with asyncio.timeout(10):
                            await child.wait()
                    if child.returncode is None:
                        child.kill()
                        await child.wait()
            if proxy is not None:
                await proxy.close()
            await broker.stop()
            notify.close()
            sim_log.close()
            daemon_log.close()
        report = self._report(exit_code, probe, proxy, notify, watcher)
        (self.dir / "report.json").write_text(json.dumps(report, indent=2) + "\n")
        draw_plots(report, self.dir / "soak.png")
        return report

    def _sample(
        self,
        pid: int,
        probe: Path,
        proxy: SerialProxy,
        notify: NotifySocket,
        watcher: MqttWatcher,
    ) -> None:
        last = _last_probe(probe)
        self.samples.append(
            {
                "t": round(self.now(), 2),
                **proc_sample(pid),
                "tasks": last.get("tasks"),
                "lag_ms": round(1000 * last["lag_s"], 2) if "lag_s" in last else None,
                "threads": last.get("threads"),
                **{k: v for k, v in last.items() if k.startswith("malloc_")},
                "commands": proxy.commands,
                "mqtt_messages": watcher.messages,
                "frames": notify.frames,
                "dropped": notify.dropped,
                "watchdog_pings": len(notify.pings),
            }
        )

    async def _inject(
        self,
        name: str,
        proxy: SerialProxy,
        sim: asyncio.subprocess.Process,
        broker: Mosquitto,
        notify: NotifySocket,
        watcher: MqttWatcher,
        truth: GroundTruth,
    ) -> None:
        start = self.now()
        entry: dict[str, Any] = {"fault": name, "at_s": round(start, 2)}
        if name == "serial-reset":
            before = len(proxy.connections)
            await proxy.reset(OUTAGE_S)
            end = self.now()
            await self._wait_for(lambda: len(proxy.connections) > before, 15)
            await self._wait_for(lambda: len(proxy.connections[-1].first_commands) >= 2, 15)
            conn = proxy.connections[-1] if len(proxy.connections) > before else None
            first = conn.first_commands[:2] if conn else []
            entry |= {
                "expected": "reconnect; first commands STOP, STOP",
                "first_commands": [str(c) for c in first],
                "recovered": conn is not None and first == [Motion(), Motion()],
                "recovery_s": round(conn.opened - end, 2) if conn else None,
            }
        elif name == "stream-stall":
            pings_before = len(notify.pings)
            frames_before = notify.frames
            sim.send_signal(signal.SIGUSR1)  # the stream stalls; the dome goes on
            await asyncio.sleep(STOP_WITHIN_S)
            wire_after = proxy.last_motion  # what the dome was last told
            await asyncio.sleep(STALL_S - STOP_WITHIN_S)
            stops = [t for t in proxy.stop_times if t > start]
            pings_late = [t for t in notify.pings[pings_before:] if t > start + 3.0]
            sim.send_signal(signal.SIGUSR2)
            end = self.now()
            await self._wait_for(lambda: notify.frames > frames_before + 5, 30)
            resumed = notify.frames > frames_before + 5
            entry |= {
                "expected": f"dome stopped within {STOP_WITHIN_S} s; watchdog unfed; frames resume",
                "wire_motion_after_s": str(wire_after),
                "stop_after_s": round(stops[0] - start, 2) if stops else None,
                "watchdog_pings_while_stalled": len(pings_late),
                "recovered": wire_after == Motion() and not pings_late and resumed,
                # STATUS= comes every 5 s: this is an upper bound
                "recovery_s": _round(self._first_after(notify.frame_times, end, frames_before))
                if resumed
                else None,
            }
        elif name == "broker-restart":
            onlines = len(watcher.online_times)
            await broker.kill()
            await asyncio.sleep(OUTAGE_S)
            await broker.start()
            end = self.now()
            await self._wait_for(lambda: len(watcher.online_times) > onlines, 30)
            recovered = len(watcher.online_times) > onlines
            entry |= {
                "expected": "retained availability=online republished after reconnect",
                "recovered": recovered,
                "recovery_s": round(watcher.online_times[-1] - end, 2) if recovered else None,
            }
        elif name == "day-night":
            entry |= await self._day_night(sim, broker, notify, watcher, truth)
        self.fault_log.append(entry)

    async def _day_night(
        self,
        sim: asyncio.subprocess.Process,
        broker: Mosquitto,
        notify: NotifySocket,
        watcher: MqttWatcher,
        truth: GroundTruth,
    ) -> dict[str, Any]:
        """Dusk, then dawn: the daemon's log says its tracker switched, and so do the MQTT
        `track` messages (their `tracker` field), as a site's integration sees it."""
        from ptzd.sim.cli import DAWN_SIGNAL, DUSK_SIGNAL
        from ptzd.vision.config import AutoConfig

        kinds = AutoConfig()  # the soak's daemon runs the default tracker: auto
        log = self.dir / "daemon.log"
        switches: dict[str, float | None] = {}
        on_mqtt: dict[str, float | None] = {}
        frames_before = notify.frames
        light_waits: dict[str, float] = {}
        tries: dict[str, int] = {}
        for phase, sig, kind in (("night", DUSK_SIGNAL, kinds.night),
                                 ("day", DAWN_SIGNAL, kinds.day)):  # fmt: skip
            # The daemon switches only with a target (at once for a tracked one, else at the
            # next lock), so the light changes once the operator has someone whole in view
            # to lock on: two CI soaks' dawns came while the night's walker was lost and the
            # dome looked at nobody (once off the scene's side), and 15 s of an operator
            # looking each second found nobody (no target, rightly no switch: the fault
            # counted unrecovered).
            waited_from = self.now()
            while self._choice(truth) is None and self.now() - waited_from < LIGHT_WAIT_S:  # noqa: ASYNC110
                await asyncio.sleep(0.5)
            light_waits[phase] = round(self.now() - waited_from, 2)
            offset = log.stat().st_size
            began = self.now()
            sim.send_signal(sig)
            # he may have gone by the time the dome stands still: the operator tries each second
            tries[phase] = 1
            while not await self._select(broker.port, truth) and self.now() - began < NIGHT_S:
                await asyncio.sleep(1.0)
                tries[phase] += 1
            switched_now = functools.partial(_switched_to, log, offset, kind)
            named = functools.partial(watcher.named_after, began, kind)

            def both(log_says: Callable[[], bool] = switched_now,
                     mqtt_says: Callable[[], float | None] = named) -> bool:  # fmt: skip
                return log_says() and mqtt_says() is not None

            await self._wait_for(both, NIGHT_S)
            switched = switched_now()
            switches[phase] = round(self.now() - began, 2) if switched else None
            seen = named()
            on_mqtt[phase] = None if seen is None else round(seen - began, 2)
            await asyncio.sleep(max(0.0, began + NIGHT_S - self.now()))
        return {
            "ended_s": round(self.now(), 2),
            "expected": f"switch to {kinds.night} within {NIGHT_S:g} s of dusk and to "
            f"{kinds.day} within {NIGHT_S:g} s of dawn, in the log and in MQTT's track "
            "messages; frames keep coming",
            "night_switch_s": switches["night"],
            "day_switch_s": switches["day"],
            "night_on_mqtt_s": on_mqtt["night"],
            "day_on_mqtt_s": on_mqtt["day"],
            # how long each change of light waited for someone in view, and how many times
            # the operator then tried to select
            "light_waited_s": light_waits,
            "select_tries": tries,
            "recovered": None not in (*switches.values(), *on_mqtt.values())
            and notify.frames > frames_before,
            "recovery_s": switches["day"],
        }

    async def _select(self, mqtt_port: int, truth: GroundTruth) -> bool:
        """Pick the biggest walker well inside the view and fully visible (ground truth of
        the frame shown; `truth`, the wide scene's, says who is hidden) and send
        `{"select": box}` over MQTT, as an operator would; whether one was selected.

        Fully visible: an operator draws the box on someone he can see. Picked by the size
        of his ground-truth box alone, the soak selected walker 0 behind the hedge (30 of 51
        selections in a 1-hour run, 0.14-0.40 of him visible), whose amodal box is mostly
        hedge, and the tracker learnt the hedge.

        The box is the one of the frame the daemon has when the command arrives
        (`shown_record`): the daemon applies it to the next frame it processes, about
        `SIM_CAMERA_LATENCY_S` older than the simulator's newest. Taken from the newest, the
        box was 3 frames ahead: its centre 3-18 px across from the walker's in the frame the
        daemon had (five selections of a 5-minute soak, walkers 34-85 px wide), and the
        tracker learnt a slice of background with him.

        Only once the dome has stood still for `STILL_FRAMES` frames (or after
        `STILL_WAIT_S`): a picture that moves between the frame boxed and the frame the box
        lands on puts it beside the walker. With the dome turning at 15-20 deg/s, as it was
        at every first selection, the box (then of the newest frame) lay 20 px beside a
        19 px wide walker, and the tracker started on the grass. The command also carries
        the boxed frame's time (`"ts"`), so the daemon moves the box by whatever the dome
        turned between that frame and the one the box lands on (it may start turning again
        in between: in a 1-hour soak it did 0.28 s after the frame walker 13 was boxed on)."""
        import aiomqtt

        camera = self.dir / "sim" / "camera.jsonl"
        waited = 0.0
        while waited < STILL_WAIT_S and not dome_still(
            _last_json_lines(camera, STILL_FRAMES), STILL_FRAMES
        ):
            await asyncio.sleep(0.1)
            waited += 0.1
        shown = self._choice(truth)
        if shown is None:
            return False
        record, drawn_ts, (walker, box) = shown
        with contextlib.suppress(aiomqtt.MqttError):
            async with aiomqtt.Client("127.0.0.1", mqtt_port, timeout=5) as client:
                payload = json.dumps({"select": [round(v, 1) for v in box],
                                      "ts": round(drawn_ts, 3)})  # fmt: skip
                await client.publish(f"ptzd/{CAMERA}/ptz", payload.encode(), qos=1)
                self.selections.append(
                    {"t": round(self.now(), 2), "frame": record["frame"], "walker": walker,
                     "waited_s": round(waited, 1)}
                )  # fmt: skip
                return True
        return False

    def _choice(
        self, truth: GroundTruth
    ) -> tuple[Mapping[str, Any], float, tuple[str, list[float]]] | None:
        """The record of the frame the daemon has now, the epoch time it was rendered at
        and whom the operator would select in it (`operator_choice`); None if nobody."""
        records = _last_json_lines(self.dir / "sim" / "groundtruth_view.jsonl", SHOWN_LOOKBACK)
        record = shown_record(records, SIM_CAMERA_LATENCY_S)
        if record is None:
            return None
        choice = operator_choice(record, truth)
        if choice is None:
            return None
        # the epoch time of the frame boxed, as the daemon's track messages give it (the
        # newest record was rendered about now): the daemon moves the box with the dome
        drawn_ts = time.time() - (float(records[-1]["t"]) - float(record["t"]))
        return record, drawn_ts, choice

    def _centring(self) -> dict[str, Any]:
        path = self.dir / "sim" / "groundtruth_view.jsonl"
        if not self.selections or not path.exists():
            return {}
        with path.open(encoding="utf-8") as lines:
            return selection_centring(lines, self.selections, SETTLE_FRAMES)

    @staticmethod
    def _first_after(times: list[tuple[float, int]], after: float, frames: int) -> float | None:
        for t, count in times:
            if t >= after and count > frames:
                return t - after
        return None

    @staticmethod
    async def _wait_for(predicate: Callable[[], bool], limit_s: float) -> None:
        """Wait until `predicate()` holds or `limit_s` passed. The state lives in other
        processes (sockets, files), so there is no event to await: poll at 10 Hz."""
        with contextlib.suppress(TimeoutError):
            async with asyncio.timeout(limit_s):
                while not predicate():  # noqa: ASYNC110
                    await asyncio.sleep(0.1)

    def _warm_from(self) -> float:
        """Where the leak checks start: after the warm-up, and after the first `day-night`
        (the first night builds the night tracker, whose learning memory fills up to ~8 MB
        once in its first ~60 frames and stays: a step, not a leak)."""
        opts = self.options
        cut = min(opts.warmup_s, opts.minutes * 30)
        nights = [float(f["ended_s"]) for f in self.fault_log if f["fault"] == "day-night"]
        return max([cut, *nights[:1]])

    def _report(
        self,
        exit_code: int | None,
        probe: Path,
        proxy: SerialProxy | None,
        notify: NotifySocket,
        watcher: MqttWatcher | None,
    ) -> dict[str, Any]:
        opts = self.options
        warm = [s for s in self.samples if s["t"] >= self._warm_from()]
        fds = [s["fds"] for s in warm if s["fds"] >= 0]
        threads = [s["threads"] for s in warm if s.get("threads", -1) >= 0]
        tasks = [s["tasks"] for s in warm if s["tasks"] is not None]
        lags = [1000 * v for v in _probe_lags(probe)]
        log_text = (self.dir / "daemon.log").read_text(errors="replace")
        errors = [
            line for line in log_text.splitlines()
            if '"level": "error"' in line or '"level": "critical"' in line
        ]  # fmt: skip
        elapsed = self.samples[-1]["t"] if self.samples else 0.0
        memory = rss_summary(warm)
        growth = memory["rss_anon_growth_mb"]
        gaps = [b - a for a, b in zip(notify.pings, notify.pings[1:], strict=False)]
        summary = {
            "duration_s": round(elapsed, 1),
            "daemon_exit_code": exit_code,
            "leak_checks_from_s": round(self._warm_from(), 2),
            **memory,
            "fds_min_max": [min(fds), max(fds)] if fds else None,
            "threads_min_max": [min(threads), max(threads)] if threads else None,
            "tasks_min_max": [min(tasks), max(tasks)] if tasks else None,
            "loop_lag_ms_p50": _round(_percentile(lags, 0.5)),
            "loop_lag_ms_p99": _round(_percentile(lags, 0.99)),
            "loop_lag_ms_max": _round(max(lags) if lags else None),
            "frames": notify.frames,
            "frames_dropped": notify.dropped,
            "commands": proxy.commands if proxy else 0,
            "command_rate_hz": round(proxy.commands / elapsed, 2) if proxy and elapsed else None,
            "stops": proxy.stops if proxy else 0,
            "last_motion_is_stop": bool(proxy and proxy.last_motion == Motion()),
            "last_motion": str(proxy.last_motion) if proxy else None,
            "mqtt_messages": watcher.messages if watcher else 0,
            "watchdog_pings": len(notify.pings),
            "watchdog_max_gap_s": _round(max(gaps) if gaps else None),
            "error_log_lines": len(errors),
            "unhandled_exception": "Traceback" in log_text,
        }
        checks = {
            "clean_exit": exit_code == 0,
            "dome_left_stopped": summary["last_motion_is_stop"],
            "no_unhandled_exception": not summary["unhandled_exception"],
            "heap_growth_below_limit": growth is not None and growth < opts.max_heap_growth_mb,
            "no_fd_leak": bool(fds) and max(fds) - min(fds) <= 8,
            "no_task_leak": bool(tasks) and max(tasks) - min(tasks) <= 8,
            "faults_recovered": all(f.get("recovered") for f in self.fault_log),
        }
        return {
            "options": {
                "minutes": opts.minutes,
                "faults": list(opts.faults),
                "virtual_clock": opts.virtual_clock,
                "sample_s": opts.sample_s,
                "warmup_s": opts.warmup_s,
                "max_heap_growth_mb": opts.max_heap_growth_mb,
            },
            "summary": summary,
            "checks": checks,
            "ok": all(checks.values()),
            "faults": self.fault_log,
            "selections": self.selections,
            "centring": self._centring(),
            "samples": self.samples,
            "errors": errors[:20],
        }


def _round(value: float | None, digits: int = 2) -> float | None:
    return None if value is None else round(value, digits)


# --- the virtual-clock soak -----------------------------------------------------------------


async def run_virtual(options: SoakOptions) -> dict[str, Any]:
    """`ptzd sim --virtual-clock --acquire --loop` for N simulated minutes, probed.

    The daemon runs unattended on the looping synthetic scene: it searches, locks, follows,
    loses, goes home and searches again, for as long as asked."""
    out = options.report_dir
    out.mkdir(parents=True, exist_ok=True)
    probe = out / "probe.jsonl"
    probe.unlink(missing_ok=True)
    config: list[str] = []
    if options.fps is not None:
        # a dome streaming at a lower rate: the same scene, fewer frames per simulated second
        (out / "sim.toml").write_text(f"[sim]\nfps = {options.fps}\n")
        config = ["--config", str(out / "sim.toml")]
    start = time.monotonic()
    samples: list[dict[str, Any]] = []
    with (out / "sim.log").open("wb") as log:
        child = await asyncio.create_subprocess_exec(
            sys.executable, "-m", "ptzd.soak", "probe", str(probe),
            str(min(1.0, options.sample_s)), "--log-format",
            "json", "sim", "--virtual-clock", "--acquire", "--loop",
            "--duration", str(options.minutes * 60), *config,
            "--record", str(out / "sim"), stdout=log, stderr=log,
        )  # fmt: skip
        while child.returncode is None:
            last = _last_probe(probe)
            samples.append(
                {
                    "t": round(time.monotonic() - start, 2),
                    **proc_sample(child.pid),
                    "tasks": last.get("tasks"),
                    "lag_ms": round(1000 * last["lag_s"], 2) if "lag_s" in last else None,
                }
            )
            with contextlib.suppress(TimeoutError):
                async with asyncio.timeout(options.sample_s):
                    await child.wait()
    report = virtual_report(options, samples, child.returncode, round(time.monotonic() - start, 1))
    (out / "report.json").write_text(json.dumps(report, indent=2) + "\n")
    draw_plots(report, out / "soak.png")
    return report


def virtual_report(
    options: SoakOptions, samples: list[dict[str, Any]], exit_code: int | None, wall_s: float
) -> dict[str, Any]:
    """Summary and checks of a virtual-clock soak from its samples and the files in its
    report directory (`probe.jsonl`, `sim.log`, `sim/report.json`); also run on a finished
    run's directory to re-check it."""
    out = options.report_dir
    # warm-up: --warmup-s or the first fifth of the run, whichever is longer (at most half)
    cut = min(max(options.warmup_s, 0.2 * wall_s), 0.5 * wall_s)
    warm = [s for s in samples if s["t"] >= cut] or samples
    fds = [s["fds"] for s in warm if s.get("fds", -1) >= 0]
    threads = [s["threads"] for s in warm if s.get("threads", -1) >= 0]
    tasks = [s["tasks"] for s in warm if s.get("tasks") is not None]
    lags = [1000 * v for v in _probe_lags(out / "probe.jsonl")]
    log_text = (out / "sim.log").read_text(errors="replace")
    # say what really ran (the scene loops, so this is what was asked unless it failed)
    try:
        sim_report = json.loads((out / "sim" / "report.json").read_text())
        simulated = float(sim_report.get("duration_s", 0.0))
        frames = int(sim_report.get("frames_processed", 0))
    except (OSError, ValueError):
        simulated, frames = 0.0, 0
    memory = rss_summary(warm)
    growth = memory["rss_anon_growth_mb"]
    summary = {
        "asked_s": options.minutes * 60,
        "simulated_s": simulated,
        "frames_processed": frames,
        "wall_s": wall_s,
        "exit_code": exit_code,
        **memory,
        "fds_min_max": [min(fds), max(fds)] if fds else None,
        "threads_min_max": [min(threads), max(threads)] if threads else None,
        "tasks_min_max": [min(tasks), max(tasks)] if tasks else None,
        "loop_lag_ms_p50": _round(_percentile(lags, 0.5)),
        "loop_lag_ms_p99": _round(_percentile(lags, 0.99)),
        "unhandled_exception": "Traceback" in log_text,
    }
    # the same limits as the real-time soak's checks
    checks = {
        "clean_exit": exit_code == 0,
        "simulated_what_was_asked": simulated >= 0.99 * options.minutes * 60,
        "no_unhandled_exception": not summary["unhandled_exception"],
        "heap_growth_below_limit": growth is not None and growth < options.max_heap_growth_mb,
        "no_fd_leak": bool(fds) and max(fds) - min(fds) <= 8,
        "no_task_leak": bool(tasks) and max(tasks) - min(tasks) <= 8,
    }
    return {
        "options": {
            "minutes": options.minutes,
            "virtual_clock": True,
            "fps": options.fps,
            "max_heap_growth_mb": options.max_heap_growth_mb,
        },
        "summary": summary,
        "checks": checks,
        "ok": all(checks.values()),
        "samples": samples,
    }


# --- plots ------------------------------------------------------------------------------------

_PANELS = (
    ("rss_mb", "RSS (MB)"),
    ("rss_anon_mb", "RSS anonymous: heap (MB)"),
    ("fds", "open fds"),
    ("tasks", "asyncio tasks"),
    ("lag_ms", "event-loop lag (ms)"),
    ("commands", "Pelco commands (cumulative)"),
    ("mqtt_messages", "MQTT messages (cumulative)"),
)


def draw_plots(report: dict[str, Any], path: Path) -> None:
    """One panel per sampled series, fault times as red lines; drawn with cv2."""
    import cv2
    import numpy as np

    samples = report.get("samples", [])
    panels = [(k, title) for k, title in _PANELS if any(s.get(k) is not None for s in samples)]
    width, panel_h, margin = 900, 150, 60
    image = np.full((panel_h * max(1, len(panels)) + 20, width, 3), 255, np.uint8)
    if not samples:
        cv2.imwrite(str(path), image)
        return
    t_end = max(s["t"] for s in samples) or 1.0

    def x_of(t: float) -> int:
        return int(margin + (width - margin - 20) * t / t_end)

    for row, (key, title) in enumerate(panels):
        top = row * panel_h + 20
        points = [(s["t"], float(s[key])) for s in samples if s.get(key) is not None]
        lo = min(v for _, v in points)
        hi = max(v for _, v in points)
        span = hi - lo or 1.0
        bottom = top + panel_h - 40

        def y_of(v: float, bottom: int = bottom, lo: float = lo, span: float = span) -> int:
            return int(bottom - (panel_h - 60) * (v - lo) / span)

        cv2.rectangle(image, (margin, top), (width - 20, bottom), (200, 200, 200), 1)
        for fault in report.get("faults", []):
            x = x_of(fault["at_s"])
            cv2.line(image, (x, top), (x, bottom), (0, 0, 220), 1)
        line = np.array([(x_of(t), y_of(v)) for t, v in points], np.int32)
        cv2.polylines(image, [line], False, (160, 60, 0), 2)
        label = f"{title}: {lo:.1f} .. {hi:.1f}"
        cv2.putText(image, label, (margin, top - 4), cv2.FONT_HERSHEY_SIMPLEX, 0.45, (0, 0, 0), 1)
    cv2.putText(image, f"t = 0 .. {t_end:.0f} s", (margin, image.shape[0] - 6),
                cv2.FONT_HERSHEY_SIMPLEX, 0.45, (0, 0, 0), 1)  # fmt: skip
    cv2.imwrite(str(path), image)


def run_soak(options: SoakOptions) -> dict[str, Any]:
    if options.virtual_clock:
        return asyncio.run(run_virtual(options))
    return asyncio.run(Soak(options).run())


if __name__ == "__main__":
    if len(sys.argv) >= 4 and sys.argv[1] == "probe":
        sys.exit(run_probed(Path(sys.argv[2]), float(sys.argv[3]), sys.argv[4:]))
    sys.exit("usage: python -m ptzd.soak probe FILE INTERVAL_S PTZD_ARGS...")
