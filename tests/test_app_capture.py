"""cv2.VideoCapture source: real decoding, paced at the file's rate, capture times attached."""

from __future__ import annotations

import asyncio
from pathlib import Path

import cv2
import numpy as np
import pytest

from ptzd.capture import CaptureError, VideoCaptureSource, is_live, parse_source
from ptzd.clock import VirtualClock


def write_video(path: Path, frames: int = 200, fps: float = 20.0) -> None:
    writer = cv2.VideoWriter(str(path), cv2.VideoWriter.fourcc(*"MJPG"), fps, (320, 240))
    assert writer.isOpened()
    rng = np.random.default_rng(1)
    background = rng.integers(60, 120, size=(240, 320, 3), dtype=np.uint8)
    for i in range(frames):
        image = background.copy()
        x = min(150 + 2 * i, 290)
        image[90:150, x : x + 20] = (30, 30, 220)
        writer.write(image)
    writer.release()


async def test_file_frames_are_decoded_and_paced_on_the_clock(tmp_path: Path) -> None:
    video = tmp_path / "walk.avi"
    write_video(video, frames=12, fps=20.0)
    clock = VirtualClock()
    source = VideoCaptureSource(str(video), clock)
    items = []

    async def consume() -> None:
        async for item in source.frames():
            items.append(item)

    task = asyncio.create_task(consume())
    # advance the clock only while the source sleeps on it: the reads happen in a thread,
    # and a clock run ahead of a slow read (a loaded machine) would stamp frames late
    while not task.done():
        deadline = clock.next_deadline()
        if deadline is None:
            await asyncio.sleep(0.005)
        else:
            clock.advance_to(deadline)
            await asyncio.sleep(0)
    await task
    assert [i.index for i in items] == list(range(12))
    assert items[0].size == (320, 240)
    times = [i.capture_time for i in items]
    assert times == sorted(times)
    assert times[-1] - times[0] == pytest.approx(11 / 20.0, abs=0.06)  # paced at 20 fps


async def test_frames_are_stamped_when_taken_not_when_they_arrive(tmp_path: Path) -> None:
    """With `latency_s` a frame's capture time is its arrival less the latency: the time
    the dome's pose is looked up for it."""
    video = tmp_path / "walk.avi"
    write_video(video, frames=3, fps=20.0)
    clock = VirtualClock(start=100.0)
    source = VideoCaptureSource(str(video), clock, paced=False, latency_s=0.25)
    times = [item.capture_time async for item in source.frames()]
    assert times == [pytest.approx(99.75)] * 3  # the clock stood still at 100 s


async def test_unopenable_source_is_a_clear_error(tmp_path: Path) -> None:
    source = VideoCaptureSource(str(tmp_path / "missing.avi"), VirtualClock())
    with pytest.raises(CaptureError) as info:
        async for _ in source.frames():
            pass
    assert "missing.avi" in str(info.value)


def test_source_kinds() -> None:
    assert parse_source("0") == 0
    assert parse_source("/dev/video2") == "/dev/video2"
    assert is_live("rtsp://cam/stream") and is_live("http://cam/video.mjpg") and is_live("1")
    assert not is_live("/data/vtest.avi")


async def test_sim_frames_can_come_without_their_pose() -> None:
    """`[sim] report_pose = false`: the daemon gets the simulator's frames as from a dome
    that reports nothing, and stamps them `latency_s` before they were rendered."""
    from types import SimpleNamespace

    from ptzd.capture import SimFrameSource
    from ptzd.sim.camera_model import Pose

    def rendered(camera: SimpleNamespace, t: float) -> None:
        frame = SimpleNamespace(image=np.zeros((4, 4, 3), np.uint8), t=t, index=0,
                                pose=Pose(1.0, 2.0, 30.0))  # fmt: skip
        for listener in camera.listeners:
            listener(frame)

    for report_pose, latency, pose in ((True, 0.0, Pose(1.0, 2.0, 30.0)), (False, 0.1, None)):
        camera = SimpleNamespace(listeners=[])
        source = SimFrameSource(camera, report_pose=report_pose, latency_s=latency)  # type: ignore[arg-type]
        frames = source.frames()
        rendered(camera, 5.0)
        item = await anext(frames)
        assert item.pose == pose and item.capture_time == pytest.approx(5.0 - latency)
        await frames.aclose()  # type: ignore[attr-defined]


async def test_sim_frames_can_come_jpeg_coded_as_from_the_mjpeg_camera() -> None:
    """`[sim] compress_frames`: the daemon sees what the MJPEG stream would deliver: the
    same size, the colours of small details bled into their surroundings (4:2:0 chroma)."""
    from types import SimpleNamespace

    import cv2

    from ptzd.capture import SimFrameSource
    from ptzd.sim.camera_model import Pose
    from ptzd.sim.mjpeg import jpeg_round_trip

    image = np.full((48, 64, 3), 128, np.uint8)
    image[20:26, 30:33] = (40, 90, 230)  # a small orange patch on grey
    camera = SimpleNamespace(listeners=[])
    source = SimFrameSource(camera, jpeg_quality=85)  # type: ignore[arg-type]
    frames = source.frames()
    frame = SimpleNamespace(image=image, t=1.0, index=0, pose=Pose(0.0, 0.0, 60.0))
    for listener in camera.listeners:
        listener(frame)
    item = await anext(frames)
    await frames.aclose()  # type: ignore[attr-defined]
    assert item.image.shape == image.shape and item.image.dtype == np.uint8
    np.testing.assert_array_equal(item.image, jpeg_round_trip(image, 85))
    saturation = cv2.cvtColor(item.image, cv2.COLOR_BGR2HSV)[20:26, 30:33, 1].mean()
    original = cv2.cvtColor(image, cv2.COLOR_BGR2HSV)[20:26, 30:33, 1].mean()
    assert saturation < 0.9 * original  # the patch's colour washed out
    grey = jpeg_round_trip(image[..., 0], 85)
    assert grey.shape == (48, 64)
