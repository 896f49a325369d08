"""Frame sources for the daemon: cv2.VideoCapture (file, RTSP, V4L2, MJPEG URL) or the simulator.

Every frame leaves its source as a `FrameItem` carrying its capture time on the daemon's clock
(and a `perf_counter` stamp for latency statistics), its index and, when the source knows it,
the dome pose it was taken at. Blocking reads run in a dedicated thread, never on the loop.
"""

from __future__ import annotations

import asyncio
import time
from collections.abc import AsyncIterator
from concurrent.futures import ThreadPoolExecutor
from dataclasses import dataclass
from typing import TYPE_CHECKING, Any, Protocol

import numpy as np
import numpy.typing as npt

from ptzd.clock import Clock
from ptzd.errors import PtzdError
from ptzd.logs import get_logger
from ptzd.sim.camera_model import Pose

if TYPE_CHECKING:
    from ptzd.sim.camera import SimCamera, SimFrame

Image = npt.NDArray[np.uint8]

_log = get_logger("capture")


@dataclass(frozen=True, slots=True)
class FrameItem:
    """One captured frame and where/when it was taken."""

    image: Image
    capture_time: float  # on the daemon's clock
    index: int
    pose: Pose | None = None  # the dome's pose, if the source knows it
    wall_time: float = 0.0  # time.perf_counter() at capture: latency statistics only

    @property
    def size(self) -> tuple[int, int]:
        height, width = self.image.shape[:2]
        return width, height


class FrameSource(Protocol):
    """Something that yields frames until it ends (or the consumer stops iterating)."""

    def frames(self) -> AsyncIterator[FrameItem]: ...


class CaptureError(PtzdError):
    """A capture source that cannot be opened."""

    def __init__(self, uri: str, reason: str) -> None:
        self.uri = uri
        self.reason = reason
        super().__init__(f"cannot open capture source {uri!r}: {reason}")


def parse_source(uri: str) -> str | int:
    """cv2.VideoCapture's argument: a V4L2 index for a bare number, else the string as is."""
    return int(uri) if uri.isdigit() else uri


def is_live(uri: str) -> bool:
    """Live sources (cameras, streams) are read as fast as they deliver; files are paced."""
    return uri.isdigit() or uri.startswith(("/dev/video", "rtsp://", "rtsps://", "http://",
                                            "https://"))  # fmt: skip


class VideoCaptureSource:
    """cv2.VideoCapture in its own thread. Files are paced at their frame rate on the clock."""

    def __init__(
        self, uri: str, clock: Clock, *, paced: bool | None = None, latency_s: float = 0.0
    ) -> None:
        self.uri = uri
        self.clock = clock
        self.paced = (not is_live(uri)) if paced is None else paced
        # a frame's capture time is when it was taken: this long before `read()` returns it
        self.latency_s = latency_s
        self.frames_read = 0

    async def frames(self) -> AsyncIterator[FrameItem]:
        """Frames until a file ends. A live source that was open and then ends (a camera
        reboot, a stalled HTTP stream) is reopened with backoff instead: ending would stop
        the daemon with status 0, which systemd's Restart=on-failure does not restart."""
        import random

        import cv2

        from ptzd.backoff import backoff_delay

        loop = asyncio.get_running_loop()
        live = is_live(self.uri)
        rng = random.Random(0)
        index = 0
        attempt = 0
        with ThreadPoolExecutor(max_workers=1, thread_name_prefix="capture") as pool:
            target = parse_source(self.uri)
            while True:
                capture: Any = await loop.run_in_executor(pool, lambda: cv2.VideoCapture(target))
                try:
                    if not capture.isOpened():
                        if not (live and index > 0):
                            raise CaptureError(self.uri, "cv2.VideoCapture could not open it")
                    else:
                        fps = float(capture.get(cv2.CAP_PROP_FPS) or 0.0)
                        period = 1.0 / fps if self.paced and 0 < fps < 1000 else 0.0
                        start = self.clock.now()
                        first = index
                        while True:
                            ok, image = await loop.run_in_executor(pool, capture.read)
                            if not ok:
                                break
                            if period:
                                due = start + (index - first) * period
                                delay = due - self.clock.now()
                                if delay > 0:
                                    await self.clock.sleep(delay)
                            self.frames_read += 1
                            attempt = 0
                            taken = self.clock.now() - self.latency_s
                            yield FrameItem(image, taken, index, None, time.perf_counter())
                            index += 1
                        if not live or index == first == 0:
                            _log.info("capture_ended", uri=self.uri, frames=index)
                            return
                        _log.warning("capture_lost", uri=self.uri, frames=index)
                finally:
                    await loop.run_in_executor(pool, capture.release)
                await self.clock.sleep(backoff_delay(attempt, 0.5, 10.0, rng))
                attempt += 1


class SimFrameSource:
    """The in-process simulated dome's rendered views, pose included.

    It listens from construction on, so no frame rendered after it exists is missed; it keeps
    only the latest frame (a slow consumer skips frames, it never queues them). The camera's
    `run()` must be running alongside.
    """

    def __init__(
        self,
        camera: SimCamera,
        *,
        report_pose: bool = True,
        latency_s: float = 0.0,
        jpeg_quality: int | None = None,
    ) -> None:
        self.camera = camera
        self.report_pose = report_pose  # False: as a dome that reports no pose
        self.latency_s = latency_s  # as in VideoCaptureSource
        self.jpeg_quality = jpeg_quality  # set: each frame JPEG-coded, as an MJPEG camera's
        self._latest: tuple[SimFrame, float] | None = None
        self._ready = asyncio.Event()
        camera.listeners.append(self._put)

    def _put(self, frame: SimFrame) -> None:
        self._latest = (frame, time.perf_counter())  # stamped when rendered
        self._ready.set()

    async def frames(self) -> AsyncIterator[FrameItem]:
        from ptzd.sim.mjpeg import jpeg_round_trip

        try:
            while True:
                await self._ready.wait()
                self._ready.clear()
                latest, self._latest = self._latest, None
                if latest is not None:
                    frame, wall = latest
                    pose = frame.pose if self.report_pose else None
                    taken = frame.t - self.latency_s
                    image = frame.image
                    if self.jpeg_quality is not None:
                        image = jpeg_round_trip(image, self.jpeg_quality)
                    yield FrameItem(image, taken, frame.index, pose, wall)
        finally:
            if self._put in self.camera.listeners:
                self.camera.listeners.remove(self._put)
