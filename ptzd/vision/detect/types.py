"""What every detector returns, and the interface the daemon and the CLI drive."""

from __future__ import annotations

from dataclasses import dataclass
from typing import Protocol

import numpy as np
from numpy.typing import NDArray

# Boxes are `(x, y, w, h)` in frame pixels, (x, y) the top-left corner; one definition, in metrics.
from ptzd.metrics import Box as Box
from ptzd.metrics import iou as iou

Frame = NDArray[np.uint8]
"""A BGR (H, W, 3) or grey (H, W) 8-bit image."""


@dataclass(frozen=True, slots=True)
class Detection:
    """One person found in a frame.

    `score` is in [0, 1], higher meaning more person-like; each detector documents how it maps
    its own evidence onto that range so results of different detectors can be thresholded alike.
    """

    x: float
    y: float
    w: float
    h: float
    score: float
    label: str = "person"

    @property
    def box(self) -> Box:
        return (self.x, self.y, self.w, self.h)

    def to_list(self) -> list[float]:
        """`[x, y, w, h, score]`, the row format of `ptzd detect --out`."""
        return [
            round(self.x, 2),
            round(self.y, 2),
            round(self.w, 2),
            round(self.h, 2),
            round(self.score, 4),
        ]


class Detector(Protocol):
    """Finds people in a stream of frames from one camera.

    Detectors may keep state across frames (a background model): `reset()` forgets it, and
    `camera_moving=True` tells the detector the view is changing under it.
    """

    name: str

    def detect(self, frame: Frame, *, camera_moving: bool = False) -> list[Detection]: ...

    def reset(self) -> None: ...
