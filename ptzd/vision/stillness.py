"""Where the image moved between two frames, with the camera's own motion taken out.

A colour tracker left on a background patch that matches the target (a dark pole for dark
trousers, a hedge for a green shirt, a pillar's edge) scores as well there as on the
target, and no colour test can tell them apart. What tells them apart is that people move
and poles do not: `MotionMap` warps the previous frame into this one by the camera motion
the daemon already hands the tracker (ego-motion, zoom), and marks the pixels that still
differ. The tracker asks what share of a box moved (`moving_fraction`, from an integral
image: any number of boxes at once).
"""

from __future__ import annotations

import cv2
import numpy as np

from ptzd.vision.features import to_grey
from ptzd.vision.likelihood import FloatArray, Frame

_IDENTITY = np.eye(3)


class MotionMap:
    """The moving pixels of the last frame given to `update` (none before the second).

    Every image is written into buffers allocated once per frame size: the daemon runs this
    on every frame for months, and a fresh megabyte or two per frame only churns the heap."""

    def __init__(self, diff_threshold: int) -> None:
        self._threshold = diff_threshold
        self._shape: tuple[int, int] | None = None
        self._have_previous = False
        self._known = False  # whether `_integral` holds this frame's motion
        self._pending: FloatArray = _IDENTITY.copy()  # image motion since the previous frame
        self._allocate((1, 1))

    def _allocate(self, shape: tuple[int, int]) -> None:
        self._shape = shape
        self._grey = [np.zeros(shape, np.uint8), np.zeros(shape, np.uint8)]  # this, previous
        self._warped = np.zeros(shape, np.uint8)
        self._valid = np.zeros(shape, np.uint8)
        self._full = np.full(shape, 255, np.uint8)
        self._moving = np.zeros(shape, np.uint8)
        self._integral = np.zeros((shape[0] + 1, shape[1] + 1), np.int32)

    def _load(self, frame: Frame) -> bool:
        """`frame` in grey into the current buffer; False if its size changed (start over)."""
        shape = (int(frame.shape[0]), int(frame.shape[1]))
        same = shape == self._shape
        if not same:
            self._allocate(shape)
        self._grey.reverse()  # the last current frame becomes the previous one
        if frame.ndim == 3 and frame.shape[2] == 3:
            cv2.cvtColor(frame, cv2.COLOR_BGR2GRAY, dst=self._grey[0])
        else:
            np.copyto(self._grey[0], to_grey(frame))
        return same

    def reset(self, frame: Frame) -> None:
        """Start over from `frame`: no motion known until the next one."""
        self._load(frame)
        self._have_previous = True
        self._pending = _IDENTITY.copy()
        self._known = False

    def transform(self, homography: FloatArray) -> None:
        """The image was warped by `homography` (a zoom step) since the last frame."""
        self._pending = homography @ self._pending

    def update(self, frame: Frame, ego_motion: FloatArray | None) -> None:
        """Mark what moved from the previous frame to `frame`; `ego_motion` maps the previous
        frame's pixels into this one (None: the camera did not move)."""
        same = self._load(frame)
        motion = self._pending if ego_motion is None else ego_motion @ self._pending
        self._pending = _IDENTITY.copy()
        self._known = same and self._have_previous
        self._have_previous = True
        if not self._known:
            return
        grey, previous = self._grey
        size = (grey.shape[1], grey.shape[0])
        still = np.allclose(motion, _IDENTITY)
        if not still:
            cv2.warpPerspective(previous, motion, size, dst=self._warped, flags=cv2.INTER_LINEAR)
            # the part of this frame the previous one did not see is unknown, not moving
            cv2.warpPerspective(self._full, motion, size, dst=self._valid, flags=cv2.INTER_NEAREST)
        cv2.absdiff(grey, previous if still else self._warped, dst=self._moving)
        cv2.threshold(self._moving, self._threshold, 1, cv2.THRESH_BINARY, dst=self._moving)
        if not still:
            cv2.min(self._moving, self._valid, dst=self._moving)  # 1 where valid (255), else 0
        cv2.integral(self._moving, sum=self._integral, sdepth=cv2.CV_32S)

    def moving_fraction(self, boxes: FloatArray) -> FloatArray | None:
        """Share of moving pixels in each centre-form box (M x 4); None when not known."""
        if not self._known:
            return None
        ii = self._integral
        height, width = ii.shape[0] - 1, ii.shape[1] - 1
        b = np.atleast_2d(boxes)
        x0 = np.clip(np.round(b[:, 0] - b[:, 2] / 2), 0, width).astype(np.intp)
        x1 = np.clip(np.round(b[:, 0] + b[:, 2] / 2), 0, width).astype(np.intp)
        y0 = np.clip(np.round(b[:, 1] - b[:, 3] / 2), 0, height).astype(np.intp)
        y1 = np.clip(np.round(b[:, 1] + b[:, 3] / 2), 0, height).astype(np.intp)
        count = ii[y1, x1] - ii[y0, x1] - ii[y1, x0] + ii[y0, x0]
        area = np.maximum((x1 - x0) * (y1 - y0), 1)
        fraction: FloatArray = count / area
        return fraction
