"""A loose first box fitted to the moving person in it, tracked in the framing it was drawn in.

Operators, annotators and detectors frame a person differently: tight on the outline, or
with a margin of ground round them. Every tracker learns its model from the first box, so
a margin of road becomes part of "the target". On vtest.avi, first boxes 1.3 and 1.5
times as large as ours cost the closed loop 3 and 5 of its 45 runs (docs/tracking.md
"A loose first box").

One frame's colours cannot say where the person ends (grass, gravel and other walkers sit
unevenly round them; a fit by colour contrast was tried and lost more than it won). Their
motion can: the person moves and the ground does not. `FittedTracker` starts its tracker
on the box it is given, gathers the pixels that move over the first frames (the camera's
own motion taken out by `MotionMap`), trims the sides of the box in which hardly anything
moved (`fit_to_motion`), and starts the tracker again on the trimmed box. Every box it
answers is in the framing it was given (the same centre offset and margins, in proportion
to the person), so the control and MQTT see the kind of box they were handed.
"""

from __future__ import annotations

from dataclasses import dataclass

import cv2
import numpy as np
from numpy.typing import NDArray

from ptzd.logs import get_logger
from ptzd.vision.config import FirstBoxConfig, TrackerConfig
from ptzd.vision.particle_filter import ego_motion_matrix, zoom_homography
from ptzd.vision.stillness import MotionMap, camera_still
from ptzd.vision.tracking import Box, Tracker, TrackResult, TrackState

# A box under this many pixels either way (in the frame) is too small to trim strips from.
_MIN_SIDE = 8


def fit_to_motion(moving: NDArray[np.uint8], box: Box, config: FirstBoxConfig) -> Box:
    """`box` (x, y, w, h) with the still strips at its sides trimmed, at most
    `config.max_trim` of the box from each side.

    A strip is still when under `config.strip_fraction` of its pixels are on the person,
    that is: set in `moving` (1 moved, 0 did not), or lying between two set pixels of the
    same row or column within half the box's size outside it. The second part is for
    people in plain cloth, whose motion is at their outline: the edge they left behind them
    may lie outside a box that follows them, and inside it only the edge they walk into.
    A side with nothing trimmed keeps its edge as drawn (a tight box comes back as it went
    in); so does the whole box when under `config.min_moving_fraction` of it moved, when
    under `config.min_person_share` of what would be kept is on the person, or when it is
    under 8 pixels either way inside the frame."""
    height, width = moving.shape[:2]
    x, y, w, h = box
    x0, y0 = max(round(x), 0), max(round(y), 0)
    x1, y1 = min(round(x + w), width), min(round(y + h), height)
    if x1 - x0 < _MIN_SIDE or y1 - y0 < _MIN_SIDE:
        return box
    if float(moving[y0:y1, x0:x1].mean()) < config.min_moving_fraction:
        return box
    reach_x, reach_y = round(w / 2), round(h / 2)
    ex0, ex1 = max(x0 - reach_x, 0), min(x1 + reach_x, width)
    ey0, ey1 = max(y0 - reach_y, 0), min(y1 + reach_y, height)
    along_rows = _between(moving[y0:y1, ex0:ex1], axis=1)[:, x0 - ex0 : x1 - ex0]
    along_cols = _between(moving[ey0:ey1, x0:x1], axis=0)[y0 - ey0 : y1 - ey0, :]
    person = along_rows | along_cols
    kept_x, kept_y = _kept(person.mean(axis=0), config), _kept(person.mean(axis=1), config)
    # motion this thin inside what is kept is not a person's outline filled in (a plain
    # figure whose trailing edge did not change, a box lagging its walker): keep the box
    if float(person[slice(*kept_y), slice(*kept_x)].mean()) < config.min_person_share:
        return box
    fx, fw = _fitted_side(x, w, x0, x1 - x0, kept_x)
    fy, fh = _fitted_side(y, h, y0, y1 - y0, kept_y)
    return (fx, fy, fw, fh)


def _between(moving: NDArray[np.uint8], axis: int) -> NDArray[np.bool_]:
    """Pixels at or between the first and the last set pixel of their line along `axis`."""
    set_ = moving.astype(bool)
    after_first = np.logical_or.accumulate(set_, axis=axis)
    before_last = np.flip(np.logical_or.accumulate(np.flip(set_, axis=axis), axis=axis), axis=axis)
    between: NDArray[np.bool_] = after_first & before_last
    return between


def _fitted_side(
    start: float, size: float, first: int, length: int, kept: tuple[int, int]
) -> tuple[float, float]:
    """(start, size) of a box along one axis trimmed to the strips `kept` ([from, to) of
    its `length` whole pixels in the frame, the first of which is `first`); an untrimmed
    end keeps its edge as drawn."""
    kept_from, kept_to = kept
    low = start if kept_from == 0 else float(first + kept_from)
    if kept_to == length:
        return (start, size) if kept_from == 0 else (low, start + size - low)
    return low, float(first + kept_to) - low


def _kept(profile: NDArray[np.float64], config: FirstBoxConfig) -> tuple[int, int]:
    """[start, end) of `profile` with its ends under `strip_fraction` cut off."""
    size = len(profile)
    limit = int(config.max_trim * size)
    start = 0
    while start < limit and profile[start] < config.strip_fraction:
        start += 1
    end = size
    while size - end < limit and profile[end - 1] < config.strip_fraction:
        end -= 1
    return start, end


@dataclass(frozen=True)
class Framing:
    """How a drawn box sits on the fitted one: its centre's offset in fitted widths and
    heights, and its size in fitted sizes (the identity: the fitted box is the drawn one)."""

    dx: float = 0.0
    dy: float = 0.0
    kw: float = 1.0
    kh: float = 1.0

    @classmethod
    def between(cls, fitted: Box, drawn: Box) -> Framing:
        fx, fy, fw, fh = fitted
        x, y, w, h = drawn
        return cls(
            dx=((x + w / 2) - (fx + fw / 2)) / fw,
            dy=((y + h / 2) - (fy + fh / 2)) / fh,
            kw=w / fw,
            kh=h / fh,
        )

    def drawn(self, fitted: Box) -> Box:
        """The drawn framing of a fitted box."""
        fx, fy, fw, fh = fitted
        cx, cy = fx + fw / 2 + self.dx * fw, fy + fh / 2 + self.dy * fh
        w, h = self.kw * fw, self.kh * fh
        return (cx - w / 2, cy - h / 2, w, h)


_AS_DRAWN = Framing()


class FittedTracker:
    """`tracker`, started again on its first box fitted to the person's motion, answering in
    the first box's framing.

    `rescale` and `resembles` go to the tracker as they are: a zoom keeps the framing (it is
    in proportion), and the boxes `resembles` is asked about are a detector's, fitted to
    the person as tightly as the fitted box is."""

    def __init__(self, tracker: Tracker, config: TrackerConfig) -> None:
        self.tracker = tracker
        self._config = config.first_box
        self._motion = MotionMap(config.stillness.diff_threshold)
        self._moved: NDArray[np.uint8] | None = None  # moved at least once in the frames so far
        self._waiting = 0  # frames of motion still to gather before the fit
        self._framing = _AS_DRAWN
        self._log = get_logger("vision")

    @property
    def framing(self) -> Framing:
        """How the drawn box sits on the box the tracker follows (the identity until the
        fit, and after a fit that trimmed too little to matter)."""
        return self._framing

    def init(self, frame: NDArray[np.uint8], box: Box) -> None:
        self.tracker.init(frame, box)
        self._framing = _AS_DRAWN
        self._moved = None
        self._waiting = self._config.frames
        self._motion.reset(frame)

    def update(
        self, frame: NDArray[np.uint8], ego_motion: NDArray[np.float64] | None = None
    ) -> TrackResult:
        result = self.tracker.update(frame, ego_motion)
        box = result.box
        if self._waiting:
            self._gather(frame, ego_motion)
            if self._waiting == 0 and self._moved is not None:
                if result.state is TrackState.TRACKING:
                    box = self._refit(frame, box)
                self._moved = None
        if self._framing == _AS_DRAWN:  # not refitted: the tracker's own answer, untouched
            return result
        return TrackResult(self._framing.drawn(box), result.state, result.confidence,
                           result.velocity)  # fmt: skip

    def _gather(self, frame: NDArray[np.uint8], ego_motion: NDArray[np.float64] | None) -> None:
        motion = None if ego_motion is None else ego_motion_matrix(ego_motion)
        self._motion.update(frame, motion)
        moving = self._motion.moving()
        if moving is None:  # a new frame size: the motion so far says nothing about this one
            self._waiting, self._moved = 0, None
            return
        self._waiting -= 1
        if self._moved is None:
            self._moved = moving.copy()
            return
        if motion is not None:
            self._warp_moved(motion)
        cv2.max(self._moved, moving, dst=self._moved)

    def _warp_moved(self, homography: NDArray[np.float64]) -> None:
        """The motion gathered so far, moved with the image."""
        if self._moved is None or camera_still(homography):
            return
        size = (self._moved.shape[1], self._moved.shape[0])
        warped = cv2.warpPerspective(self._moved, homography, size, flags=cv2.INTER_NEAREST)
        self._moved = np.asarray(warped, dtype=np.uint8)

    def _refit(self, frame: NDArray[np.uint8], box: Box) -> Box:
        """Start the tracker again on `box` fitted to the gathered motion, if that trims
        enough to matter; the box the tracker now follows."""
        assert self._moved is not None
        fitted = fit_to_motion(self._moved, box, self._config)
        # a margin drawn round a person is a good share of the box and lies above his head
        # or below his feet; a tight box has little, and at its sides (a still arm, a
        # planted leg)
        cfg = self._config
        small = fitted[2] * fitted[3] < cfg.refit_area_below * box[2] * box[3]
        if not (small and fitted[3] < cfg.refit_height_below * box[3]):
            return box
        self._framing = Framing.between(fitted, box)
        self.tracker.init(frame, fitted)
        self._log.info(
            "first_box_fitted",
            bbox=[round(v, 1) for v in box],
            fitted=[round(v, 1) for v in fitted],
        )
        return fitted

    def rescale(self, factor: float, center: tuple[float, float]) -> None:
        self.tracker.rescale(factor, center)
        if self._waiting:
            homography = zoom_homography(factor, center)
            self._motion.transform(homography)
            self._warp_moved(homography)

    def resembles(self, frame: NDArray[np.uint8], box: Box) -> bool:
        return self.tracker.resembles(frame, box)
