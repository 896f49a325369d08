"""Faults in the pipeline, each with its expected recovery (docs/reliability.md):

- the camera stream stalls: the dome is stopped once tracks go stale, the pipeline waits and
  tracks again when frames return;
- garbage frames and a resolution change: no crash, frames keep being processed;
- CPU starvation: frames are dropped (never queued), the dome ends stopped;
- wall-clock jump: nothing in the pipeline reads wall time except the MQTT timestamp.
"""

from __future__ import annotations

import asyncio
import re
import subprocess
import sys
import time
from collections.abc import AsyncIterator
from pathlib import Path

import numpy as np
import pytest

from ptzd.app import Daemon
from ptzd.capture import FrameItem
from ptzd.clock import RealClock
from ptzd.pelco.codec import FrameParser, Motion
from ptzd.pelco.link import PelcoLink
from ptzd.vision.tracking import make_tracker
from tests.test_app import BOX, SIZE, config, pty_pair, scene

STOP = Motion()


class Wire:
    """Incremental reader of the motions the daemon wrote to the pty master."""

    def __init__(self, master: int) -> None:
        self.master = master
        self.parser = FrameParser()
        self.motions: list[Motion] = []

    def read(self) -> list[Motion]:
        import contextlib
        import os

        with contextlib.suppress(BlockingIOError):
            while chunk := os.read(self.master, 65536):
                frames = self.parser.feed(chunk)
                self.motions += [f.command for f in frames if isinstance(f.command, Motion)]
        return self.motions


class ScriptedSource:
    """Walker frames, then a stall, then noise frames, then a bigger resolution."""

    def __init__(self, clock: RealClock, *, stall_s: float = 1.5, fps: float = 20.0) -> None:
        self.clock, self.stall_s, self.period = clock, stall_s, 1 / fps
        self.stalled = asyncio.Event()
        self.resumed = asyncio.Event()
        self.phase = "walk"

    def _item(self, image: np.ndarray, index: int) -> FrameItem:
        return FrameItem(image, self.clock.now(), index, None, time.perf_counter())

    async def frames(self) -> AsyncIterator[FrameItem]:
        index = 0
        for step in range(20):  # 1 s walking right
            yield self._item(scene(BOX[0] + 3 * step), index)
            index += 1
            await asyncio.sleep(self.period)
        self.phase = "stall"
        self.stalled.set()
        await asyncio.sleep(self.stall_s)  # the stream stalls: no frame, no error
        self.resumed.set()
        self.phase = "garbage"
        rng = np.random.default_rng(1)
        for _ in range(10):
            yield self._item(rng.integers(0, 256, (SIZE[1], SIZE[0], 3), dtype=np.uint8), index)
            index += 1
            await asyncio.sleep(self.period)
        self.phase = "resized"
        for step in range(20):  # the camera switches to 640x480
            big = np.repeat(np.repeat(scene(BOX[0] + step), 2, axis=0), 2, axis=1)
            yield self._item(big, index)
            index += 1
            await asyncio.sleep(self.period)


async def test_stall_stops_the_dome_and_garbage_and_resize_do_not_crash() -> None:
    clock = RealClock()
    with pty_pair() as (master, port):
        cfg = config(port, max_track_age_s=0.3)
        wire = Wire(master)
        async with PelcoLink(cfg.serial, clock=clock) as link:
            source = ScriptedSource(clock)
            daemon = Daemon(cfg, source=source, link=link, clock=clock,
                            tracker_factory=lambda: make_tracker(cfg.tracker),
                            initial_box=BOX)  # fmt: skip
            task = asyncio.create_task(daemon.run())
            await asyncio.wait_for(source.stalled.wait(), 10)
            moving_before = any(m.pan > 0 for m in wire.read())
            processed_at_stall = daemon.stats.frames_processed
            await asyncio.wait_for(source.resumed.wait(), 10)
            during_stall = wire.read()
            assert not task.done()  # the pipeline waits for frames; it does not give up
            assert moving_before, "the dome never followed the walker"
            assert during_stall[-1] == STOP, "a stalled stream must leave the dome stopped"
            assert daemon.stats.stale_stops >= 1
            await asyncio.wait_for(task, 20)
        motions = wire.read()
    assert daemon.stats.frames_processed > processed_at_stall + 5  # garbage + resized frames
    assert motions[-1] == STOP


@pytest.fixture
def cpu_hogs() -> object:
    """Two busy processes: on this 2-core box they compete with the daemon for every core."""
    hogs = [subprocess.Popen([sys.executable, "-c", "while True: pass"]) for _ in range(2)]
    yield hogs
    for hog in hogs:
        hog.kill()
        hog.wait(timeout=10)


async def test_cpu_starvation_drops_frames_and_stays_safe(cpu_hogs: object) -> None:
    clock = RealClock()
    with pty_pair() as (master, port):
        cfg = config(port, max_track_age_s=0.3)
        wire = Wire(master)
        async with PelcoLink(cfg.serial, clock=clock) as link:
            source = _BlockingWalker(clock)
            daemon = Daemon(cfg, source=source, link=link, clock=clock,
                            tracker_factory=lambda: make_tracker(cfg.tracker),
                            initial_box=BOX)  # fmt: skip
            await asyncio.wait_for(daemon.run(), 30)
        motions = wire.read()
    stats = daemon.stats
    assert stats.frames_captured == source.count
    assert stats.frames_processed + stats.frames_dropped == stats.frames_captured
    assert stats.frames_dropped > 0  # starved: frames were dropped, not queued
    assert motions[0] == STOP and motions[-1] == STOP
    assert not any(m.pan < 0 for m in motions)  # never driven the wrong way


class _BlockingWalker:
    """60 frames at 50 fps; every 10th frame the process gets no CPU for 0.4 s, then the
    frames the camera delivered meanwhile arrive in one burst, already old."""

    count = 60

    def __init__(self, clock: RealClock) -> None:
        self.clock = clock

    async def frames(self) -> AsyncIterator[FrameItem]:
        index = 0
        while index < self.count:
            if index % 10 == 9:
                time.sleep(0.4)  # noqa: ASYNC251 -- blocks the loop on purpose, as starvation would
                now = self.clock.now()
                for late in range(min(5, self.count - index)):  # the backlog, oldest first
                    image = scene(BOX[0] + index)
                    yield FrameItem(
                        image, now - 0.02 * (5 - late), index, None, time.perf_counter()
                    )
                    index += 1
                continue
            yield FrameItem(
                scene(BOX[0] + index), self.clock.now(), index, None, time.perf_counter()
            )
            index += 1
            await asyncio.sleep(0.02)


ROOT = Path(__file__).resolve().parents[1]
# Wall time is allowed only where a timestamp is published for humans or other hosts.
WALL_CLOCK_ALLOWED = {"ptzd/app.py"}


def test_only_monotonic_time_drives_the_pipeline() -> None:
    """A wall-clock jump (NTP step, RTC reset) cannot stall or speed up anything: every
    timer, deadline and age uses `time.monotonic` / `time.perf_counter` via the Clock."""
    pattern = re.compile(r"\btime\.time\(|datetime\.now\(|datetime\.utcnow\(|time\.localtime\(")
    users = {
        str(path.relative_to(ROOT))
        for path in (ROOT / "ptzd").rglob("*.py")
        if pattern.search(path.read_text())
    }
    assert users <= WALL_CLOCK_ALLOWED | _sim_and_tools(users), users


def _sim_and_tools(users: set[str]) -> set[str]:
    # simulator/recording/reporting code may stamp files with wall time; it drives nothing
    return {u for u in users if u.startswith(("ptzd/sim/", "ptzd/soak", "ptzd/closed_loop"))}


async def test_wall_clock_jump_changes_nothing(monkeypatch: pytest.MonkeyPatch) -> None:
    """time.time() jumps back a day mid-run: the dome still follows and stops cleanly."""
    clock = RealClock()
    real_time = time.time
    jump = {"offset": 0.0}
    monkeypatch.setattr(time, "time", lambda: real_time() + jump["offset"])
    with pty_pair() as (master, port):
        cfg = config(port)
        wire = Wire(master)
        async with PelcoLink(cfg.serial, clock=clock) as link:
            from tests.test_app import MovingTarget

            daemon = Daemon(cfg, source=MovingTarget(clock, frames=40), link=link, clock=clock,
                            tracker_factory=lambda: make_tracker(cfg.tracker),
                            initial_box=BOX)  # fmt: skip
            task = asyncio.create_task(daemon.run())
            await asyncio.sleep(0.6)
            jump["offset"] = -86_400.0
            await asyncio.wait_for(task, 20)
        motions = wire.read()
    assert daemon.stats.stale_stops == 0
    assert any(m.pan > 0 for m in motions) and motions[-1] == STOP
