"""The tracker API the daemon and `ptzd track` use.

Boxes are `(x, y, w, h)` in pixels of the frame passed to `update`, `x, y` the top-left
corner. A tracker is not thread-safe; one worker owns it.
"""

from __future__ import annotations

from dataclasses import dataclass
from enum import StrEnum
from typing import Protocol

import numpy as np
from numpy.typing import NDArray

from ptzd.vision.config import TrackerConfig

Box = tuple[float, float, float, float]


def centre_box(box: Box, *, check: bool = False) -> NDArray[np.float64]:
    """`(x, y, w, h)` in the centre form `[cx, cy, w, h]` the trackers work in. With `check`
    (an init box): ValueError unless it is finite with a positive size."""
    x, y, w, h = (float(v) for v in box)
    if check and (not all(np.isfinite([x, y, w, h])) or w <= 0 or h <= 0):
        raise ValueError(f"box must have finite coordinates and positive size, got {box}")
    return np.array([x + w / 2, y + h / 2, w, h])


class TrackState(StrEnum):
    """What the tracker believes about its target this frame."""

    TRACKING = "tracking"
    OCCLUDED = "occluded"  # similarity below the threshold: coasting, model frozen
    LOST = "lost"  # occluded for too long (or never initialised); box is the last guess


@dataclass(frozen=True)
class TrackResult:
    """One frame's answer: box (x, y, w, h), state, confidence in 0..1, velocity px/frame."""

    box: Box
    state: TrackState
    confidence: float
    velocity: tuple[float, float]


class Tracker(Protocol):
    """A single-target tracker."""

    def init(self, frame: NDArray[np.uint8], box: Box) -> None:
        """Start tracking the target inside `box` of `frame` (BGR, HxWx3).

        It starts over: a tracker initialised again on a new target behaves exactly as a new
        tracker would (the daemon keeps one per camera, so its buffers are allocated once)."""
        ...

    def update(
        self, frame: NDArray[np.uint8], ego_motion: NDArray[np.float64] | None = None
    ) -> TrackResult:
        """Track into the next frame.

        `ego_motion` maps previous-frame pixels to this frame's pixels: a shift `(dx, dy)`
        or a 3x3 homography. It is applied in the prediction step.
        """
        ...

    def rescale(self, factor: float, center: tuple[float, float]) -> None:
        """The image scale changed by `factor` about `center` (a zoom step)."""
        ...

    def resembles(self, frame: NDArray[np.uint8], box: Box) -> bool:
        """Whether `box` of `frame` (the frame last given to `update`) looks like the target
        to this tracker's appearance model: the test a re-identification must pass."""
        ...


def make_tracker(config: TrackerConfig) -> Tracker:
    """The tracker `config.kind` names, its first box fitted to the person's motion when
    `config.first_box` is enabled (ptzd/vision/first_box.py)."""
    if config.first_box.enabled:
        from ptzd.vision.first_box import FittedTracker

        return FittedTracker(make_bare_tracker(config), config)
    return make_bare_tracker(config)


def make_bare_tracker(config: TrackerConfig) -> Tracker:
    """The tracker `config.kind` names, following the first box as it is given."""
    from ptzd.vision.color import ColorLikelihood
    from ptzd.vision.particle_filter import ParticleTracker

    if config.kind == "color":
        return ParticleTracker(config, ColorLikelihood(config.color, config.gmm))
    if config.kind == "rf":
        from ptzd.vision.rf import RfTracker

        return RfTracker(config)
    if config.kind == "svm":
        from ptzd.vision.svm import SvmTracker

        return SvmTracker(config)
    if config.kind == "auto":
        from ptzd.vision.auto import AutoTracker

        return AutoTracker(config)
    raise ValueError(f"unknown tracker kind {config.kind!r}")  # pragma: no cover - Literal
