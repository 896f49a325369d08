"""`kind = "auto"`: a day tracker on colour frames, a night tracker on monochrome ones.

A day/night dome switches to monochrome at dusk (its IR-cut filter out) and back at dawn,
often while it follows someone. A colour model learned by day does not match the same
person in near-infrared grey, and colour histograms say little on grey frames, so the
colour tracker loses the target on the switch and tracks worse at night. This tracker
looks at every frame's share of coloured pixels (`colour_share`, thresholds with a dead
band in `AutoConfig`) and runs `AutoConfig.day` or `AutoConfig.night`. When the frames change
while the target is TRACKING, the other tracker starts on the target's box carried into
the new frame (the camera's motion and the target's own); while it is occluded or lost
the switch waits for the next `init` (a re-acquisition) or for the running tracker to
find the target again, so that no model is learned on a box that may not hold the target.
"""

from __future__ import annotations

import numpy as np
from numpy.typing import NDArray

from ptzd.logs import get_logger
from ptzd.vision.config import TrackerConfig, TrackerKind
from ptzd.vision.first_box import FittedTracker
from ptzd.vision.particle_filter import apply_homography, ego_motion_matrix, zoom_homography
from ptzd.vision.tracking import (
    Box,
    Tracker,
    TrackResult,
    TrackState,
    centre_box,
    make_bare_tracker,
)

# Pixels whose brightest channel is under this carry no colour to speak of (sensor noise,
# and in the simulator the black outside the wide video): they are left out.
_DARK = 16
# A pixel is coloured when its channels spread by at least this many levels. A grey frame
# comes back from a video decoder with every pixel spread by 0-3 (its YUV -> BGR rounding),
# never more; on colour footage even a washed-out view has a fifth of its pixels over it.
_COLOURED = 8


def colour_share(frame: NDArray[np.uint8], step: int = 8) -> float:
    """Share (0..1) of the lit pixels, on every `step`-th row and column, that are coloured:
    0 for single-channel frames, for grey ones in three channels and for frames with
    nothing lit."""
    if frame.ndim == 2 or (frame.ndim == 3 and frame.shape[2] == 1):
        return 0.0
    if frame.ndim != 3 or frame.shape[2] != 3:
        raise ValueError(f"frame must be HxW, HxWx1 or HxWx3, got shape {frame.shape}")
    grid = frame[::step, ::step]
    b, g, r = grid[..., 0], grid[..., 1], grid[..., 2]
    # channel by channel: 7x faster than max/min along the last axis of a strided view
    brightest = np.maximum(np.maximum(b, g), r)
    lit = brightest >= _DARK
    lit_count = np.count_nonzero(lit)
    if lit_count == 0:
        return 0.0
    # brightest >= darkest per pixel, so the uint8 difference cannot wrap
    coloured = (brightest - np.minimum(np.minimum(b, g), r) >= _COLOURED) & lit
    return float(np.count_nonzero(coloured)) / float(lit_count)


class AutoTracker:
    """Runs `config.auto.day` on colour frames and `config.auto.night` on monochrome ones."""

    def __init__(self, config: TrackerConfig) -> None:
        if config.kind != "auto":
            raise ValueError(f"AutoTracker needs kind = 'auto', got {config.kind!r}")
        self._config = config
        self._trackers: dict[TrackerKind, Tracker] = {}  # one of each, buffers kept
        self._mono: bool | None = None  # what the last frame looked like
        self._kind: TrackerKind | None = None
        self._last: TrackResult | None = None
        self._log = get_logger("vision")

    @property
    def kind(self) -> TrackerKind | None:
        """The tracker running now (None before the first `init`)."""
        return self._kind

    def _tracker(self, kind: TrackerKind) -> Tracker:
        if kind not in self._trackers:
            self._trackers[kind] = make_bare_tracker(self._config.model_copy(update={"kind": kind}))
        return self._trackers[kind]

    def _is_mono(self, frame: NDArray[np.uint8]) -> tuple[bool, float]:
        auto = self._config.auto
        share = colour_share(frame, auto.sample_step)
        if share < auto.mono_below:
            return True, share
        if share > auto.colour_above:
            return False, share
        if self._mono is None:  # in the band with nothing to go on: the nearer side
            return share < (auto.mono_below + auto.colour_above) / 2, share
        return self._mono, share

    def _kind_for(self, mono: bool) -> TrackerKind:
        return self._config.auto.night if mono else self._config.auto.day

    def init(self, frame: NDArray[np.uint8], box: Box) -> None:
        self._mono, share = self._is_mono(frame)
        kind = self._kind_for(self._mono)
        if self._kind is not None and kind != self._kind:
            self._log_switch(kind, share, box, "init")
        tracker = self._tracker(kind)
        tracker.init(frame, box)
        self._kind = kind
        self._last = TrackResult(box, TrackState.TRACKING, 1.0, (0.0, 0.0))

    def update(
        self, frame: NDArray[np.uint8], ego_motion: NDArray[np.float64] | None = None
    ) -> TrackResult:
        if self._kind is None or self._last is None:
            raise RuntimeError("init() the tracker before update()")
        self._mono, share = self._is_mono(frame)
        wanted = self._kind_for(self._mono)
        if wanted != self._kind and self._last.state is TrackState.TRACKING:
            box = self._carried(self._last, ego_motion)
            self._log_switch(wanted, share, box, "frames")
            tracker = self._tracker(wanted)
            tracker.init(frame, box)
            self._kind = wanted
            # the new tracker's first answer, on the frame it started on
            self._last = tracker.update(frame)
            return self._last
        self._last = self._trackers[self._kind].update(frame, ego_motion)
        return self._last

    def _log_switch(self, kind: TrackerKind, share: float, box: Box, reason: str) -> None:
        """`reason`: "frames" (they changed while the target was tracked) or "init" (a new
        lock on frames of the other kind)."""
        self._log.info(
            "tracker_switched",
            previous=self._kind,
            kind=kind,
            reason=reason,
            colour_share=round(share, 3),
            bbox=[round(v, 1) for v in box],
        )

    @staticmethod
    def _mapped(last: TrackResult, homography: NDArray[np.float64]) -> TrackResult:
        """`last` in the pixels of the frame `homography` maps to."""
        boxes, velocities = apply_homography(
            homography, centre_box(last.box)[None, :], np.array([last.velocity], dtype=float)
        )
        cx, cy, w, h = (float(v) for v in boxes[0])
        vx, vy = (float(v) for v in velocities[0])
        return TrackResult((cx - w / 2, cy - h / 2, w, h), last.state, last.confidence, (vx, vy))

    def _carried(self, last: TrackResult, ego_motion: NDArray[np.float64] | None) -> Box:
        """The last box moved into this frame: the camera's motion, then the target's."""
        if ego_motion is not None:
            last = self._mapped(last, ego_motion_matrix(ego_motion))
        x, y, w, h = last.box
        return (x + last.velocity[0], y + last.velocity[1], w, h)

    def rescale(self, factor: float, center: tuple[float, float]) -> None:
        if self._kind is None:
            return
        self._trackers[self._kind].rescale(factor, center)
        if self._last is not None:  # a switch on the next frame starts from the zoomed box
            self._last = self._mapped(self._last, zoom_homography(factor, center))

    def resembles(self, frame: NDArray[np.uint8], box: Box) -> bool:
        if self._kind is None:
            return False
        return self._trackers[self._kind].resembles(frame, box)


def running_kind(tracker: Tracker | None, configured: str) -> str | None:
    """The likelihood `tracker` runs now: `auto`'s day or night one, else the `configured`
    kind (None without a tracker)."""
    if tracker is None:
        return None
    if isinstance(tracker, FittedTracker):
        tracker = tracker.tracker
    if isinstance(tracker, AutoTracker):
        return tracker.kind
    return configured
