"""svm's local scan: a grid of boxes around the box, the two-frame rule, and where a hidden
walker may be.

LK and the learned PF follow the target from where it was. When they lose it (it came out
of an occlusion away from them, or the cloud drifted onto a passer-by the SVM half
believes), a grid of boxes of the target's size around the box is scored by the SVM, and
the best box is taken only when it is found on two frames running (`FoundTwice`): once, it
was half a body low on legs and ground as often as on the walker.
"""

from __future__ import annotations

import numpy as np
from numpy.typing import NDArray

from ptzd.vision.likelihood import FloatArray
from ptzd.vision.particle_filter import apply_homography

# `not_behind`: how far behind (box widths) a hidden walker may be found, and the slowest
# velocity (box widths a frame) that has a heading.
_MAX_BEHIND = 0.5
_HEADING_MIN_SPEED = 0.02


def grid_around(box: FloatArray, radius: float, step: float, shape: tuple[int, ...]) -> FloatArray:
    """Boxes of `box`'s size (cx, cy, w, h), centres `step` box sizes apart, within `radius`
    box widths left and right and half a box height up and down; centres in the frame."""
    w, h = float(box[2]), float(box[3])
    dx = np.arange(-radius, radius + 1e-9, step) * w
    dy = np.arange(-0.5, 0.5 + 1e-9, step) * h
    gx, gy = np.meshgrid(box[0] + dx, box[1] + dy)
    keep = (gx >= 0) & (gx < shape[1]) & (gy >= 0) & (gy < shape[0])
    n = int(keep.sum())
    return np.column_stack([gx[keep], gy[keep], np.full(n, w), np.full(n, h)])


def not_behind(
    boxes: FloatArray, origin: FloatArray, velocity: FloatArray, width: float
) -> NDArray[np.bool_]:
    """Which `boxes` (cx, cy, w, h) lie no more than half a box `width` behind `origin`
    along `velocity`'s heading: where a walker hidden at `origin` may be by now. A hidden
    walker walks on; what he walked past stands behind him. All of them for a velocity
    under 0.02 box widths a frame, too slow to have a heading (a walker who had stopped)."""
    speed = float(np.hypot(*velocity))
    if speed < _HEADING_MIN_SPEED * width:
        return np.ones(boxes.shape[0], bool)
    ahead = (boxes[:, :2] - origin[:2]) @ (velocity / speed)
    keep: NDArray[np.bool_] = ahead >= -_MAX_BEHIND * width
    return keep


class FoundTwice:
    """A scan's find is taken when the next frame's scan finds a box within half a box of
    it (centre to centre)."""

    def __init__(self) -> None:
        self.candidate: FloatArray | None = None  # the last scan's find

    def offer(self, found: FloatArray | None) -> bool:
        """This frame's find (None: the scan found nothing, or did not run): taken?"""
        previous, self.candidate = self.candidate, found
        return (
            found is not None
            and previous is not None
            and bool(np.all(np.abs(found[:2] - previous[:2]) <= 0.5 * found[2:]))
        )

    def clear(self) -> None:
        self.candidate = None

    def transform(self, homography: FloatArray) -> None:
        """The find moves with the image (ego-motion, zoom)."""
        if self.candidate is not None:
            moved, _ = apply_homography(homography, self.candidate[None], np.zeros((1, 2)))
            self.candidate = moved[0]
