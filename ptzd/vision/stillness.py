"""Where the image moved between two frames, with the camera's own motion taken out.

A colour tracker left on a background patch that matches the target (a dark pole for dark
trousers, a hedge for a green shirt, a pillar's edge) scores as well there as on the
target, and no colour test can tell them apart. What tells them apart is that people move
and poles do not: `MotionMap` warps the previous frame into this one by the camera motion
the daemon already hands the tracker (ego-motion, zoom), and marks the pixels that still
differ. The tracker asks what share of a box moved (`moving_fraction`, from an integral
image: any number of boxes at once). `StillCounter` lets a tracker go of a box in which
nothing moved for a while; `motion_weights` tilts the learned trackers' particle weights
towards the boxes in which something moves.
"""

from __future__ import annotations

import cv2
import numpy as np
from numpy.typing import NDArray

from ptzd.vision.features import to_grey
from ptzd.vision.likelihood import FloatArray, Frame

_IDENTITY = np.eye(3)
# np.allclose's tolerance against the identity (atol 1e-8, rtol 1e-5), written out: its
# Python wrapper cost more than the rest of the still test, twice a frame
_IDENTITY_TOLERANCE = 1e-8 + 1e-5 * _IDENTITY
_OPEN_KERNEL = np.ones((3, 3), np.uint8)


def camera_still(homography: FloatArray | None) -> bool:
    """No image motion was handed in with a frame (none, or the identity)."""
    return homography is None or _is_identity(homography)


def _is_identity(homography: FloatArray) -> bool:
    return bool((np.abs(homography - _IDENTITY) <= _IDENTITY_TOLERANCE).all())


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
        self._opened = np.zeros(shape, np.uint8)
        self._integral = np.zeros((shape[0] + 1, shape[1] + 1), np.int32)
        self._corner_limits = np.array([[shape[1]], [shape[0]], [shape[1]], [shape[0]]], float)

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
        zoomed = not camera_still(self._pending)  # a zoom step since the last frame
        motion = self._pending if ego_motion is None else ego_motion @ self._pending
        self._pending = _IDENTITY.copy()
        self._known = same and self._have_previous
        self._have_previous = True
        if not self._known:
            return
        grey, previous = self._grey
        size = (grey.shape[1], grey.shape[0])
        still = _is_identity(motion)
        if not still:
            cv2.warpPerspective(previous, motion, size, dst=self._warped, flags=cv2.INTER_LINEAR)
            # the part of this frame the previous one did not see is unknown, not moving
            cv2.warpPerspective(self._full, motion, size, dst=self._valid, flags=cv2.INTER_NEAREST)
        cv2.absdiff(grey, previous if still else self._warped, dst=self._moving)
        cv2.threshold(self._moving, self._threshold, 1, cv2.THRESH_BINARY, dst=self._moving)
        if not still:
            cv2.min(self._moving, self._valid, dst=self._moving)  # 1 where valid (255), else 0
        if zoomed:
            # A zoom step rescales the whole image, and the previous frame warped to match is
            # resampled twice: every sharp edge comes out a pixel or two off and "moves".
            # Those lines are thin; what a walker leaves is not: an opening keeps the blobs.
            cv2.morphologyEx(self._moving, cv2.MORPH_OPEN, _OPEN_KERNEL, dst=self._opened)
            self._moving, self._opened = self._opened, self._moving
        cv2.integral(self._moving, sum=self._integral, sdepth=cv2.CV_32S)

    def moving(self) -> NDArray[np.uint8] | None:
        """This frame's pixels: 1 moved, 0 did not; None when not known. The buffer is
        overwritten by the next `update`: copy what must outlive it."""
        return self._moving if self._known else None

    def moving_fraction(self, boxes: FloatArray) -> FloatArray | None:
        """Share of moving pixels in each centre-form box (M x 4); None when not known."""
        if not self._known:
            return None
        ii = self._integral
        b = np.atleast_2d(boxes)
        half = b[:, 2:] / 2
        # corners x0, y0, x1, y1 as rows, clipped to the image in one call
        corners = np.round(np.concatenate([b[:, :2] - half, b[:, :2] + half], axis=1).T)
        np.minimum(np.maximum(corners, 0, out=corners), self._corner_limits, out=corners)
        x0, y0, x1, y1 = corners.astype(np.intp)
        count = ii[y1, x1] - ii[y0, x1] - ii[y1, x0] + ii[y0, x0]
        area = np.maximum((x1 - x0) * (y1 - y0), 1)
        fraction: FloatArray = count / area
        return fraction


class StillCounter:
    """Counts the frames in a row in which a tracker's box did not move: `count` says when
    there were `frames` of them (0 turns the test off). Unknown motion (the first frame, a
    new frame size) neither counts nor resets."""

    def __init__(self, frames: int, min_fraction: float) -> None:
        self.frames = frames
        self.min_fraction = min_fraction
        self.run = 0

    def reset(self) -> None:
        self.run = 0

    def count(self, moved: float | None) -> bool:
        """Add this frame's moving fraction of the box; whether the box is still."""
        if moved is None:
            return False
        self.run = self.run + 1 if moved < self.min_fraction else 0
        return bool(self.frames) and self.run >= self.frames

    def count_box(self, motion: MotionMap, box: FloatArray) -> bool:
        """`count` with the moving fraction of centre-form `box` in `motion`."""
        moved = motion.moving_fraction(box[None])
        return self.count(None if moved is None else float(moved[0]))


def motion_weights(
    moved: FloatArray | None, floor: float, min_fraction: float
) -> FloatArray | None:
    """Per-box weights in [floor, 1] from the boxes' moving fractions: 1 for the box in which
    most moved, `floor` for boxes in which nothing did, the square root of the share of the
    most in between (a box half on the walker still counts for much).

    None - no evidence, leave the likelihood alone - when motion is unknown or under
    `min_fraction` moved in every box: a target standing still, or hidden, is then judged
    on its appearance alone, as it would be without this."""
    if moved is None or floor >= 1.0:
        return None
    top = float(moved.max()) if moved.size else 0.0
    if top < min_fraction:
        return None
    weights: FloatArray = floor + (1.0 - floor) * np.sqrt(moved / top)
    return weights
