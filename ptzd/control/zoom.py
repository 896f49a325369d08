"""Zoom layers (seed 002 eqs. 32-38) with guards against zoom hunting.

The target's box should stay within [rate_small, rate_big] x its desired size (eqs. 32-33).
When it falls outside, one zoom step is taken: the layer changes by ±1 and the step aims at
the size eqs. 35-38 give (the desired size nudged back inside the band, with the desired
aspect ratio of eq. 34); the ratio of that size to the current one is the step's scale
factor, which sizes the zoom pulse and rescales the tracker's box.

Beyond the seed: zoom in only when the target is near the centre, slow, and would still be
well inside the view after the step; zoom out early when it nears an edge or moves fast;
a condition must hold for `confirm_s`, steps are at least `min_dwell_s` apart, and a step
against the previous one (a reversal) waits until `reversal_guard_s` after the last
reversal, so there is at most one reversal per `reversal_guard_s`.
"""

from __future__ import annotations

from dataclasses import dataclass
from enum import IntEnum

from ptzd.control.config import ZoomConfig


class ZoomDirection(IntEnum):
    OUT = -1
    IN = 1


@dataclass(frozen=True)
class Box:
    """Axis-aligned box in view pixels: top-left corner, width, height."""

    x: float
    y: float
    w: float
    h: float

    @property
    def cx(self) -> float:
        return self.x + self.w / 2

    @property
    def cy(self) -> float:
        return self.y + self.h / 2

    def scaled_about(self, factor: float, cx: float, cy: float) -> Box:
        """This box as seen after zooming by `factor` about the image point (cx, cy)."""
        return Box(cx + (self.x - cx) * factor, cy + (self.y - cy) * factor,
                   self.w * factor, self.h * factor)  # fmt: skip

    def resized(self, w: float, h: float) -> Box:
        """Same centre, new size."""
        return Box(self.cx - w / 2, self.cy - h / 2, w, h)


@dataclass(frozen=True)
class ZoomStep:
    """One zoom step: direction, the layer after it, the scale factor it aims at (>1 = in),
    the target's box expected after it (eqs. 35-38, about the view centre) and why."""

    direction: ZoomDirection
    layer: int
    factor: float
    box_after: Box
    reason: str


def seed_resize(
    box: Box, desired_w: float, desired_h: float, cfg: ZoomConfig
) -> tuple[Box, float] | None:
    """Eqs. 32-38: the aspect-preserving box after a zoom step, or None inside the band.

    Returns the box (same centre, new size) and the scale factor of the dimension that broke
    the band (>1 zoom in, <1 zoom out). With `size_measure = "seed"` width is tested before
    height, as in the seed; with "height" only the height cases apply (a walking person's
    width swings with every stride, the height does not).
    """
    use_width = cfg.size_measure == "seed"
    ratio = desired_w / desired_h  # eq. 34
    upper_w, upper_h = desired_w * cfg.rate_big, desired_h * cfg.rate_big  # eq. 32
    lower_w, lower_h = desired_w * cfg.rate_small, desired_h * cfg.rate_small  # eq. 33
    if use_width and box.w < lower_w:  # eqs. 35-36, zoom in
        w_new = lower_w * cfg.rate_big
        return box.resized(w_new, w_new / ratio), w_new / box.w
    if box.h < lower_h:
        h_new = lower_h * cfg.rate_big
        return box.resized(h_new * ratio, h_new), h_new / box.h
    if use_width and box.w > upper_w:  # eqs. 37-38, zoom out
        w_new = upper_w * cfg.rate_small
        return box.resized(w_new, w_new / ratio), w_new / box.w
    if box.h > upper_h:
        h_new = upper_h * cfg.rate_small
        return box.resized(h_new * ratio, h_new), h_new / box.h
    return None


class ZoomController:
    """Decides zoom steps and counts zoom layers; pure, time passed in as `now`."""

    def __init__(self, cfg: ZoomConfig) -> None:
        self.cfg = cfg
        self.layer = 0
        self.desired: tuple[float, float] | None = None
        self._pending: tuple[ZoomDirection, float] | None = None  # direction, since
        self._last_step: tuple[ZoomDirection, float] | None = None
        self._last_reversal = -float("inf")
        self.reversals = 0

    def set_desired(self, w: float, h: float) -> None:
        """The size to hold (the seed's w_initial, h_initial)."""
        if w <= 0 or h <= 0:
            raise ValueError(f"desired size must be positive, got {w}x{h}")
        self.desired = (w, h)

    def set_desired_from_box(self, box: Box, frame_height: int) -> None:
        """The seed's rule (the initial box), or `target_height` x frame height if set."""
        if self.cfg.target_height > 0:
            h = self.cfg.target_height * frame_height
            self.set_desired(h * box.w / box.h, h)
        else:
            self.set_desired(box.w, box.h)

    def reset_guards(self) -> None:
        self._pending = None

    def update(
        self,
        box: Box,
        frame_size: tuple[int, int],
        speed: float,
        now: float,
        *,
        can_in: bool = True,
        can_out: bool = True,
    ) -> ZoomStep | None:
        """One decision. `speed`: target image speed in frame widths per second;
        `can_in`/`can_out`: False at the lens's end stops (no step, no layer change)."""
        cfg = self.cfg
        if not cfg.enabled or self.desired is None:
            return None
        width, height = frame_size
        candidate = self._candidate(box, width, height, speed)
        if candidate is None or not (can_in if candidate[0] > 0 else can_out):
            self._pending = None
            return None
        direction, factor, reason = candidate
        if self._pending is None or self._pending[0] != direction:
            self._pending = (direction, now)
        if now - self._pending[1] < cfg.confirm_s:
            return None
        if not self._allowed(direction, now):
            return None
        layer = self.layer + int(direction)
        if not cfg.min_layer <= layer <= cfg.max_layer:
            return None
        box_after = self._after(box, factor, width, height)
        if self._last_step is not None and self._last_step[0] != direction:
            self._last_reversal = now
            self.reversals += 1
        self._last_step = (direction, now)
        self._pending = None
        self.layer = layer
        return ZoomStep(direction, layer, factor, box_after, reason)

    def _allowed(self, direction: ZoomDirection, now: float) -> bool:
        if self._last_step is None:
            return True
        last_direction, last_time = self._last_step
        if now - last_time < self.cfg.min_dwell_s:
            return False
        reversal = last_direction != direction
        return not (reversal and now - self._last_reversal < self.cfg.reversal_guard_s)

    def _after(self, box: Box, factor: float, width: int, height: int) -> Box:
        assert self.desired is not None
        seed = seed_resize(box, *self.desired, self.cfg)
        moved = box.scaled_about(factor, width / 2, height / 2)
        if seed is None or (seed[1] > 1) != (factor > 1):  # an edge/speed step: plain scaling
            return moved
        return moved.resized(seed[0].w, seed[0].h)

    def _candidate(
        self, box: Box, width: int, height: int, speed: float
    ) -> tuple[ZoomDirection, float, str] | None:
        cfg = self.cfg
        assert self.desired is not None
        edge = cfg.edge_margin
        near_edge = (
            box.x < edge * width
            or box.y < edge * height
            or box.x + box.w > (1 - edge) * width
            or box.y + box.h > (1 - edge) * height
        )
        seed = seed_resize(box, *self.desired, cfg)
        if seed is not None and seed[1] < 1:
            return ZoomDirection.OUT, seed[1], "too big"
        if near_edge:
            return ZoomDirection.OUT, cfg.rate_small, "near edge"
        if speed > cfg.fast_speed:
            return ZoomDirection.OUT, cfg.rate_small, "fast"
        if seed is None:
            return None
        # Too small: zoom in only if slow, central and still well inside afterwards.
        factor = seed[1]
        if speed > cfg.slow_speed:
            return None
        ex = (box.cx - width / 2) / (width / 2)
        ey = (box.cy - height / 2) / (height / 2)
        if max(abs(ex), abs(ey)) > cfg.center_radius:
            return None
        after = box.scaled_about(factor, width / 2, height / 2)
        m = cfg.inside_margin
        inside = (
            after.x >= m * width
            and after.y >= m * height
            and after.x + after.w <= (1 - m) * width
            and after.y + after.h <= (1 - m) * height
        )
        if not inside:
            return None
        return ZoomDirection.IN, factor, "too small"
