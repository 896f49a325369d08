"""The seed's 9-region field of view (fig. 14b) with a hysteretic central stop region.

Each axis is classified on its own into -1 (left/up... see `Region`), 0 (stop) or +1, so the
pair gives the nine regions. An axis enters the stop state only once the target is within
`stop_enter` of the centre line and leaves it only past `stop_leave` (> stop_enter), so a
target hovering near the border of the stop region does not start and stop the motor
every frame.
"""

from __future__ import annotations

from dataclasses import dataclass


class AxisBand:
    """Hysteretic stop band of one axis, on errors normalised to [-1, 1] (edge = ±1)."""

    def __init__(self, stop_enter: float, stop_leave: float) -> None:
        if not 0 < stop_enter < stop_leave:
            raise ValueError(f"need 0 < stop_enter < stop_leave, got {stop_enter}, {stop_leave}")
        self.stop_enter = stop_enter
        self.stop_leave = stop_leave
        self.stopped = True  # a fresh band starts in the stop state (camera at rest)

    def reset(self) -> None:
        self.stopped = True

    def update(self, error: float) -> int:
        """-1, 0 (stop) or +1 for the normalised error, with hysteresis."""
        magnitude = abs(error)
        if self.stopped:
            if magnitude > self.stop_leave:
                self.stopped = False
        elif magnitude < self.stop_enter:
            self.stopped = True
        if self.stopped:
            return 0
        return 1 if error > 0 else -1


@dataclass(frozen=True)
class Region:
    """One of the nine regions: column -1/0/+1 (left/centre/right), row -1/0/+1 (up/centre/down
    in image terms, i.e. row +1 means the target is below the centre)."""

    column: int
    row: int

    @property
    def is_stop(self) -> bool:
        return self.column == 0 and self.row == 0

    @property
    def index(self) -> int:
        """0..8 in reading order (0 = top-left, 4 = stop region, 8 = bottom-right)."""
        return (self.row + 1) * 3 + (self.column + 1)


class NineRegionFov:
    """Classifies a target position into the nine regions with per-axis hysteresis."""

    def __init__(self, stop_enter: float, stop_leave: float) -> None:
        self.pan = AxisBand(stop_enter, stop_leave)
        self.tilt = AxisBand(stop_enter, stop_leave)

    def reset(self) -> None:
        self.pan.reset()
        self.tilt.reset()

    def update(self, error_x: float, error_y: float) -> Region:
        """`error_x`/`error_y`: target offset from the centre over the half width/height."""
        return Region(self.pan.update(error_x), self.tilt.update(error_y))
