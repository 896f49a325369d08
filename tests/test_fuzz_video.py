"""Videos of odd sizes and formats through the capture and track paths.

Each either works or fails with a clear one-line error (exit 2), never a traceback:
1x1 frames, grey and 16-bit PNG sequences (cv2 converts them to 8-bit BGR), a single 4K
frame, an AVI whose header claims 0 fps, and a file that is not a video at all.
"""

from __future__ import annotations

import json
import struct
import subprocess
import sys
from collections.abc import Callable
from pathlib import Path

import cv2
import numpy as np
import pytest

from ptzd.capture import CaptureError, VideoCaptureSource
from ptzd.clock import RealClock


def _sequence(directory: Path, stem: str, image: np.ndarray, count: int = 4) -> str:
    for i in range(count):
        frame = np.roll(image, i, axis=1)  # something moves
        assert cv2.imwrite(str(directory / f"{stem}_{i:03d}.png"), frame)
    return str(directory / f"{stem}_%03d.png")


def _avi(path: Path, size: tuple[int, int], frames: int = 5, fps: float = 10.0) -> str:
    writer = cv2.VideoWriter(str(path), cv2.VideoWriter.fourcc(*"MJPG"), fps, size)
    assert writer.isOpened()
    rng = np.random.default_rng(0)
    for _ in range(frames):
        writer.write(rng.integers(0, 255, (size[1], size[0], 3), dtype=np.uint8))
    writer.release()
    return str(path)


def _zero_fps_avi(path: Path) -> str:
    """An AVI whose main and stream headers both say 0 fps (VideoWriter refuses to write one)."""
    _avi(path, (64, 48))
    data = bytearray(path.read_bytes())
    avih = data.index(b"avih") + 8
    data[avih : avih + 4] = struct.pack("<I", 0)  # dwMicroSecPerFrame
    strh = data.index(b"strh") + 8
    data[strh + 20 : strh + 28] = struct.pack("<II", 1, 0)  # dwScale, dwRate
    path.write_bytes(bytes(data))
    return str(path)


def _grey(d: Path) -> tuple[str, str]:
    image = np.zeros((48, 64), np.uint8)
    image[10:30, 20:30] = 220
    return _sequence(d, "grey", image), "20,10,10,20"


def _deep(d: Path) -> tuple[str, str]:
    image = np.zeros((48, 64, 3), np.uint16)
    image[10:30, 20:30] = (60000, 1000, 30000)
    return _sequence(d, "deep", image), "20,10,10,20"


def _one_pixel(d: Path) -> tuple[str, str]:
    return _avi(d / "tiny.avi", (1, 1)), "0,0,1,1"


def _four_k(d: Path) -> tuple[str, str]:
    image = np.zeros((2160, 3840, 3), np.uint8)
    image[1000:1300, 1800:1950] = (0, 0, 255)
    return _sequence(d, "big", image, count=1), "1800,1000,150,300"


def _zero_fps(d: Path) -> tuple[str, str]:
    return _zero_fps_avi(d / "zero.avi"), "20,10,10,20"


def _not_a_video(d: Path) -> tuple[str, str]:
    path = d / "junk.avi"
    path.write_bytes(b"RIFF" + bytes(range(256)) * 8)
    return str(path), "0,0,4,4"


VIDEOS: dict[str, Callable[[Path], tuple[str, str]]] = {
    "grey": _grey,
    "16bit": _deep,
    "1x1": _one_pixel,
    "4k-single": _four_k,
    "zero-fps": _zero_fps,
    "not-a-video": _not_a_video,
}


@pytest.mark.parametrize("name", list(VIDEOS))
def test_track_cli_works_or_fails_clearly(tmp_path: Path, name: str) -> None:
    video, init = VIDEOS[name](tmp_path)
    out = tmp_path / "out.json"
    run = subprocess.run(
        [sys.executable, "-m", "ptzd", "track", video, "--init", init, "--out", str(out)],
        capture_output=True,
        text=True,
        timeout=90,
    )
    assert "Traceback" not in run.stderr, run.stderr
    assert run.returncode in (0, 2), run.stderr
    if run.returncode == 2:
        assert run.stderr.strip().splitlines()[-1].startswith("ptzd: error:")
    else:
        assert out.exists() and json.loads(out.read_text())
    if name == "not-a-video":
        assert run.returncode == 2


@pytest.mark.parametrize("name", list(VIDEOS))
async def test_capture_source_yields_bgr_frames_or_capture_error(tmp_path: Path, name: str) -> None:
    video, _ = VIDEOS[name](tmp_path)
    source = VideoCaptureSource(video, RealClock(), paced=True)  # pacing must survive 0 fps
    shapes = []
    try:
        async for item in source.frames():
            shapes.append(item.image.shape)
            assert item.image.dtype == np.uint8 and item.image.ndim == 3
    except CaptureError as exc:
        assert name == "not-a-video", exc
        return
    assert name != "not-a-video"
    assert shapes and len(set(shapes)) == 1
