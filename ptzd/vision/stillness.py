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
from numpy.typing import NDArray

from ptzd.vision.features import to_grey
from ptzd.vision.likelihood import FloatArray, Frame

_IDENTITY = np.eye(3)


class MotionMap:
    """The moving pixels of the last frame given to `update` (none before the second)."""

    def __init__(self, diff_threshold: int) -> None:
        self._threshold = diff_threshold
        self._previous: NDArray[np.uint8] | None = None
        self._pending: FloatArray = _IDENTITY.copy()  # image motion since `_previous`
        self._integral: NDArray[np.int32] | None = None

    def reset(self, frame: Frame) -> None:
        """Start over from `frame`: no motion known until the next one."""
        self._previous = np.ascontiguousarray(to_grey(frame))
        self._pending = _IDENTITY.copy()
        self._integral = None

    def transform(self, homography: FloatArray) -> None:
        """The image was warped by `homography` (a zoom step) since the last frame."""
        self._pending = homography @ self._pending

    def update(self, frame: Frame, ego_motion: FloatArray | None) -> None:
        """Mark what moved from the previous frame to `frame`; `ego_motion` maps the previous
        frame's pixels into this one (None: the camera did not move)."""
        grey = np.ascontiguousarray(to_grey(frame))
        previous = self._previous
        motion = self._pending if ego_motion is None else ego_motion @ self._pending
        self._previous, self._pending = grey, _IDENTITY.copy()
        if previous is None or previous.shape != grey.shape:
            self._integral = None
            return
        size = (grey.shape[1], grey.shape[0])
        if np.allclose(motion, _IDENTITY):
            warped: NDArray[np.uint8] = previous
            valid: NDArray[np.uint8] | None = None
        else:
            warped = np.asarray(
                cv2.warpPerspective(previous, motion, size, flags=cv2.INTER_LINEAR), np.uint8
            )
            # the part of this frame the previous one did not see is unknown, not moving
            valid = np.asarray(
                cv2.warpPerspective(
                    np.full_like(previous, 255), motion, size, flags=cv2.INTER_NEAREST
                ),
                np.uint8,
            )
        moving = (cv2.absdiff(grey, warped) > self._threshold).astype(np.uint8)
        if valid is not None:
            moving[valid == 0] = 0
        self._integral = np.asarray(cv2.integral(moving), np.int32)

    def moving_fraction(self, boxes: FloatArray) -> FloatArray | None:
        """Share of moving pixels in each centre-form box (M x 4); None when not known."""
        if self._integral is None:
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
