"""The simulated PTZ camera: a wide source seen through the dome, frame by frame.

`SimCamera.run()` renders one view per frame period on the injected clock: it moves the dome
to the frame's capture time, picks the wide frame for that time, warps it with the camera
model and hands the result (with its capture time and the exact pose rendered) to every
subscriber: in-process consumers (`frames()`), the MJPEG server and the recorder. Serial
frames reach the dome through `link` (a `SerialLink`), fed by a pty, TCP or in-process bytes.

On a `VirtualClock` a run is bit-for-bit repeatable; on the real clock a late frame is
skipped rather than rendered late, like a camera whose sensor does not wait for the reader.
"""

from __future__ import annotations

import asyncio
import json
import math
from collections.abc import AsyncIterator, Callable
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING, Any, TextIO

from ptzd.clock import Clock
from ptzd.logs import get_logger
from ptzd.mailbox import Mailbox
from ptzd.pelco.codec import Frame, encode
from ptzd.sim.camera_model import CameraModel, Image, Pose, PreparedWide
from ptzd.sim.config import SimConfig
from ptzd.sim.dome import Dome
from ptzd.sim.endpoint import SerialLink
from ptzd.vision.features import to_bgr, to_grey

if TYPE_CHECKING:
    from ptzd.sim.sources import WideSource

_log = get_logger("sim.camera")


@dataclass(frozen=True, slots=True)
class SimFrame:
    """One rendered view: pixels, capture time on the camera's clock, and what was rendered."""

    image: Image
    t: float  # capture time on the clock the camera runs on
    index: int  # rendered frame number, 0 = first frame of the run
    video_frame: int  # index of the wide frame rendered
    pose: Pose


FrameListener = Callable[[SimFrame], None]


def command_to_json(frame: Frame) -> dict[str, Any]:
    """A decoded frame as JSON-ready data: type name and fields of the command."""
    command = frame.command
    fields: dict[str, Any] = {}
    for name in getattr(command, "__dataclass_fields__", {}):
        value = getattr(command, name)
        fields[name] = value.name.lower() if hasattr(value, "name") else value
    return {
        "protocol": str(frame.protocol),
        "address": frame.address,
        "command": type(command).__name__,
        **fields,
        "hex": frame.raw.hex(" "),
    }


class Recorder:
    """`--record DIR`: camera.jsonl, serial.jsonl and (with ground truth) groundtruth_view.jsonl.

    Times are seconds since the run started. Lines are flushed as written, so a soak test can
    read them while the run goes on.
    """

    def __init__(self, directory: str | Path) -> None:
        self.directory = Path(directory)
        self._files: dict[str, TextIO] = {}

    def open(self, *, ground_truth: bool) -> None:
        self.directory.mkdir(parents=True, exist_ok=True)
        names = ["camera", "serial", *(["groundtruth_view"] if ground_truth else [])]
        for name in names:
            # kept open for the whole run and closed by `close()`
            self._files[name] = open(  # noqa: SIM115
                self.directory / f"{name}.jsonl", "w", buffering=1
            )

    def write(self, name: str, record: dict[str, Any]) -> None:
        stream = self._files.get(name)
        if stream is not None:
            stream.write(json.dumps(record, separators=(",", ":")) + "\n")

    def close(self) -> None:
        for stream in self._files.values():
            stream.close()
        self._files.clear()


class SourceEnded(Exception):  # noqa: N818 - a signal, not a failure
    """The wide source has no frame for this time (a video played once reached its end)."""


class SimCamera:
    """Wide source + dome + clock -> rendered views, and the dome's serial link."""

    def __init__(
        self,
        source: WideSource,
        config: SimConfig,
        clock: Clock,
        *,
        loop: bool = False,
        recorder: Recorder | None = None,
        dome: Dome | None = None,
    ) -> None:
        self.source = source
        self.config = config
        self.clock = clock
        self.loop = loop
        self.recorder = recorder
        self.model = CameraModel(
            source.size, config.wide_hfov, (config.view_width, config.view_height)
        )
        self.dome = dome if dome is not None else Dome(config, start_time=clock.now())
        self.fps = config.fps if config.fps is not None else source.fps
        self.link = SerialLink(self.handle_frame, clock, baudrate=config.baudrate)
        self.listeners: list[FrameListener] = []
        self.epoch = clock.now()
        self.frames_rendered = 0
        self.frames_skipped = 0
        self.foreign_frames = 0  # frames addressed to another dome on the same line
        # the wide frame last read, ready to warp: renders faster than the source reuse it
        self._prepared: tuple[int, PreparedWide] | None = None
        # night mode switched at run time (the soak's `day-night`), on top of night_after_s
        self.night = False

    # --- serial --------------------------------------------------------------------------

    def handle_frame(self, frame: Frame, t: float) -> bytes | None:
        """A decoded frame that finished arriving at `t`; returns reply bytes, if any."""
        if self.recorder is not None:
            self.recorder.write("serial", {"t": t - self.epoch, **command_to_json(frame)})
        if frame.address != self.config.address:
            self.foreign_frames += 1
            return None
        reply = self.dome.command(frame.command, t)
        if reply is None:
            return None
        return encode(reply, protocol=frame.protocol, address=self.config.address)

    # --- rendering -----------------------------------------------------------------------

    def video_frame_at(self, index: int) -> int:
        """Wide frame shown in rendered frame `index`; raises `SourceEnded` past the end."""
        video_frame = math.floor(index * self.source.fps / self.fps + 1e-9)
        count = self.source.frame_count
        if count is not None and video_frame >= count:
            if not self.loop:
                raise SourceEnded(video_frame)
            video_frame %= count
        return video_frame

    def render(self, index: int, t: float) -> SimFrame:
        """Render frame `index` captured at clock time `t` (the dome is moved to `t` first)."""
        video_frame = self.video_frame_at(index)
        self.dome.advance_to(t)
        pose = self.dome.pose
        if self._prepared is None or self._prepared[0] != video_frame:
            self._prepared = (video_frame, self.model.prepare(self.source.read(video_frame)))
        image = self.model.render(self._prepared[1], pose)
        dusk = self.config.night_after_s
        night = self.night or (dusk is not None and t - self.epoch >= dusk)
        if night and image.ndim == 3:  # a thermal view is grey already
            image = to_bgr(to_grey(image))
        frame = SimFrame(image, t, index, video_frame, pose)
        self.frames_rendered += 1
        if self.recorder is not None:
            self._record(frame)
        for listener in self.listeners:
            listener(frame)
        return frame

    def _record(self, frame: SimFrame) -> None:
        assert self.recorder is not None
        t = frame.t - self.epoch
        width, height = self.model.view_size
        self.recorder.write(
            "camera",
            {
                "t": t,
                "video_frame": frame.video_frame,
                "pan": frame.pose.pan,
                "tilt": frame.pose.tilt,
                "hfov": frame.pose.hfov,
                "width": width,
                "height": height,
            },
        )
        gt = self.source.ground_truth
        if gt is None:
            return
        boxes: dict[str, list[float] | None] = {}
        for track_id, box in gt.boxes_at(frame.video_frame).items():
            view_box = self.model.box_to_view(box, frame.pose)
            boxes[str(track_id)] = None if view_box is None else [round(v, 3) for v in view_box]
        self.recorder.write(
            "groundtruth_view",
            {"t": t, "frame": frame.index, "video_frame": frame.video_frame, "boxes": boxes},
        )

    async def run(self, duration: float | None = None) -> None:
        """Render at `fps` from now until `duration` seconds have passed or the source ends.

        The serial link runs alongside; both stop when this returns or is cancelled.
        """
        self.epoch = self.clock.now()
        period = 1.0 / self.fps
        async with asyncio.TaskGroup() as group:
            link_task = group.create_task(self.link.run())
            try:
                index = 0
                while duration is None or index * period < duration - 1e-9:
                    t = self.epoch + index * period
                    delay = t - self.clock.now()
                    if delay > 0.0:
                        await self.clock.sleep(delay)
                    elif delay < -period:  # too late for this frame: skip to the current one
                        skipped = math.floor(-delay / period)
                        self.frames_skipped += skipped
                        index += skipped
                        continue
                    try:
                        self.render(index, t)
                    except SourceEnded:
                        _log.info("source_ended", frames=self.frames_rendered)
                        break
                    index += 1
                    await asyncio.sleep(0)  # let serial bytes in between frames
            finally:
                link_task.cancel()

    async def frames(self) -> AsyncIterator[SimFrame]:
        """The latest frame each time one is rendered; a slow consumer skips, never queues."""
        mailbox: Mailbox[SimFrame] = Mailbox("sim.frames")
        self.listeners.append(mailbox.put)
        try:
            while True:
                yield await mailbox.get()
        finally:
            self.listeners.remove(mailbox.put)
