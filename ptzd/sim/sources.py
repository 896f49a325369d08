"""Wide video sources of the simulator: a decoded video file or the procedural scene.

`open_wide_source(spec)` takes a video path or `synthetic[:SEED]` (see `ptzd.sim.scene`) and
returns a `WideSource`: random access by frame index, BGR uint8 frames, optional ground truth.
Reads are cheapest in order (index, index + 1, ...): a video decodes sequentially and seeks
only when asked for a frame behind it or far ahead. Each `read` returns a fresh array the
caller owns.
"""

from __future__ import annotations

from pathlib import Path
from typing import TYPE_CHECKING, Any, Protocol

import numpy as np

from ptzd.errors import UsageError
from ptzd.sim.groundtruth import GroundTruth, load_ground_truth

if TYPE_CHECKING:
    from numpy.typing import NDArray

    Frame = NDArray[np.uint8]

# Forward gaps up to this many frames are decoded through (grab() is cheap) rather than
# seeking: a seek lands on a keyframe and decodes forward anyway, and is less exact.
_MAX_GRAB_AHEAD = 48


class WideSource(Protocol):
    """Frames of the wide (static) camera the dome looks into."""

    @property
    def size(self) -> tuple[int, int]:
        """(W, H) in pixels."""

    @property
    def fps(self) -> float: ...

    @property
    def frame_count(self) -> int | None:
        """Number of frames; None = endless."""

    @property
    def ground_truth(self) -> GroundTruth | None: ...

    def read(self, index: int) -> Frame:
        """BGR uint8 HxWx3 frame `index`; a looped source wraps, others raise `FrameIndexError`."""


class VideoSourceError(UsageError):
    """A video that cannot be opened or decoded; `path` and `reason` say which and why."""

    def __init__(self, path: str, reason: str) -> None:
        self.path = path
        self.reason = reason
        super().__init__(f"video {path}: {reason}")


class FrameIndexError(UsageError, IndexError):
    """`read(index)` past the end of a source played once (or a negative index)."""

    def __init__(self, index: int, frame_count: int) -> None:
        self.index = index
        self.frame_count = frame_count
        super().__init__(f"frame {index} is outside 0..{frame_count - 1}")


def wrap_index(index: int, frame_count: int | None, *, loop: bool) -> int:
    """The frame actually shown for `index`: wrapped when looping, else range-checked."""
    if frame_count is None:
        if index < 0:
            raise FrameIndexError(index, 0)
        return index
    if loop:
        return index % frame_count
    if not 0 <= index < frame_count:
        raise FrameIndexError(index, frame_count)
    return index


class VideoFileSource:
    """A video file decoded with cv2.VideoCapture (opened on first read or `open()`)."""

    def __init__(self, path: str, *, loop: bool = False, ground_truth: GroundTruth | None = None):
        self.path = path
        self.loop = loop
        self._ground_truth = ground_truth
        self._capture: Any = None
        self._size = (0, 0)
        self._fps = 0.0
        self._count = 0
        self._next = 0  # index of the frame the capture decodes next
        self._last: tuple[int, Frame] | None = None  # the frame decoded last, by index
        self.seeks = 0  # how many times a read had to seek (for tests and statistics)

    def open(self) -> VideoFileSource:
        """Open the file and read its properties; raises `VideoSourceError`."""
        import cv2

        if not Path(self.path).is_file():
            raise VideoSourceError(self.path, "no such file")
        capture = cv2.VideoCapture(self.path)
        if not capture.isOpened():
            raise VideoSourceError(self.path, "cv2.VideoCapture cannot open it (not a video?)")
        width = int(capture.get(cv2.CAP_PROP_FRAME_WIDTH))
        height = int(capture.get(cv2.CAP_PROP_FRAME_HEIGHT))
        count = int(capture.get(cv2.CAP_PROP_FRAME_COUNT))
        fps = float(capture.get(cv2.CAP_PROP_FPS))
        ok, first = capture.read()
        if not ok or first is None:
            capture.release()
            raise VideoSourceError(self.path, "no frame can be decoded")
        if (first.shape[1], first.shape[0]) != (width, height) or width <= 0 or height <= 0:
            width, height = first.shape[1], first.shape[0]
        if count <= 0:
            capture.release()
            raise VideoSourceError(self.path, "the container does not report a frame count")
        if not 0.0 < fps < 1000.0:
            capture.release()
            raise VideoSourceError(self.path, f"implausible frame rate {fps}")
        self._capture = capture
        self._size = (width, height)
        self._fps = fps
        self._count = count
        self._next = 1
        self._last = (0, np.ascontiguousarray(first, dtype=np.uint8))
        return self

    @property
    def size(self) -> tuple[int, int]:
        self._ensure_open()
        return self._size

    @property
    def fps(self) -> float:
        self._ensure_open()
        return self._fps

    @property
    def frame_count(self) -> int:
        """Frames the container reports (lowered if decoding ends earlier)."""
        self._ensure_open()
        return self._count

    @property
    def ground_truth(self) -> GroundTruth | None:
        return self._ground_truth

    def attach_ground_truth(self, gt: GroundTruth) -> None:
        """Use `gt` (already checked against `size`) as this video's ground truth."""
        self._ground_truth = gt

    def read(self, index: int) -> Frame:
        self._ensure_open()
        target = wrap_index(index, self._count, loop=self.loop)
        if self._last is not None and self._last[0] == target:
            return self._last[1].copy()
        frame = self._decode(target)
        if frame is None:
            # the container over-reported its length: learn the real one and retry
            self._count = target
            if target == 0:
                raise VideoSourceError(self.path, "frame 0 cannot be decoded")
            return self.read(index)
        self._last = (target, frame)
        return frame.copy()

    def close(self) -> None:
        if self._capture is not None:
            self._capture.release()
            self._capture = None

    def _ensure_open(self) -> None:
        if self._capture is None:
            self.open()

    def _decode(self, target: int) -> Frame | None:
        import cv2

        capture = self._capture
        if target < self._next or target - self._next > _MAX_GRAB_AHEAD:
            self.seeks += 1
            capture.set(cv2.CAP_PROP_POS_FRAMES, target)
            self._next = int(capture.get(cv2.CAP_PROP_POS_FRAMES))
            if self._next != target:  # a backend that cannot seek exactly: decode from the start
                capture.set(cv2.CAP_PROP_POS_FRAMES, 0)
                self._next = 0
        while self._next < target:
            if not capture.grab():
                return None
            self._next += 1
        ok, frame = capture.read()
        if not ok or frame is None:
            return None
        self._next += 1
        if frame.ndim == 2:
            frame = cv2.cvtColor(frame, cv2.COLOR_GRAY2BGR)
        return np.ascontiguousarray(frame, dtype=np.uint8)


def open_wide_source(spec: str, *, loop: bool = False, gt_path: str | None = None) -> WideSource:
    """A video path, or `synthetic` / `synthetic:SEED` (the procedural scene, seed 0 default).

    `synthetic-thermal[:SEED]` is the scene seen by a thermal camera (grey, replicated to BGR).
    `gt_path` loads a ground-truth file and checks it matches the source's frame size.
    Raises `UsageError` subclasses (`VideoSourceError`, `GroundTruthError`) on bad input.
    """
    kind, _, arg = spec.partition(":")
    if kind in ("synthetic", "synthetic-thermal"):
        from ptzd.sim.scene import SceneSource

        try:
            seed = int(arg) if arg else 0
        except ValueError:
            raise UsageError(f"{spec!r}: expected synthetic[:SEED] with an integer seed") from None
        source: SceneSource | VideoFileSource = SceneSource(
            seed, loop=loop, thermal=kind == "synthetic-thermal"
        )
    else:
        source = VideoFileSource(spec, loop=loop).open()
    if gt_path is not None:
        source.attach_ground_truth(load_ground_truth(gt_path, expected_size=source.size))
    return source
