"""Camera motion as image motion, and the dome's speed curve.

With the simulator's documented camera model (`ptzd.sim.camera_model`, shared/interfaces.md),
a pixel x_a of the view at pose a shows the ray R_a·K_a⁻¹·x_a, which the view at pose b images
at x_b ~ K_b·R_bᵀ·R_a·K_a⁻¹·x_a. The daemon feeds that homography to the tracker as ego-motion
so its particles move with the scene instead of lagging behind the camera.

A real Pelco-P dome reports no pose, so `DomeEstimate` dead-reckons one from the commands
sent through `DomeModelConfig` (the daemon's belief about the dome's speed curve).
"""

from __future__ import annotations

import math
from collections import deque

import numpy as np
import numpy.typing as npt

from ptzd.control.config import DomeModelConfig
from ptzd.pelco.codec import MAX_SPEED as PELCO_MAX_SPEED
from ptzd.sim.camera_model import Pose, intrinsics, rotation

Matrix = npt.NDArray[np.float64]

_HISTORY = 256  # commands remembered by DomeEstimate: at 20 Hz, over 12 s of changes

__all__ = [
    "DomeEstimate",
    "Pose",
    "apply_homography",
    "byte_for_rate",
    "focal_ratio",
    "hfov_after_factor",
    "rate_for_byte",
    "view_homography",
]


def view_homography(size: tuple[int, int], before: Pose, after: Pose) -> Matrix:
    """3x3 homography taking pixels of the view at `before` to the view at `after`."""
    width, height = size
    k_a = intrinsics(width, height, before.hfov)
    k_b = intrinsics(width, height, after.hfov)
    h: Matrix = k_b @ rotation(after.pan, after.tilt).T @ rotation(before.pan, before.tilt)
    h = h @ np.linalg.inv(k_a)
    normalised: Matrix = h / h[2, 2]
    return normalised


def apply_homography(h: Matrix, x: float, y: float) -> tuple[float, float]:
    """Map one pixel through a homography."""
    u, v, w = h @ np.array([x, y, 1.0])
    return float(u / w), float(v / w)


def focal_ratio(hfov_before: float, hfov_after: float) -> float:
    """Image scale factor of a zoom from `hfov_before` to `hfov_after` (>1 = zoom in)."""
    return math.tan(math.radians(hfov_before) / 2) / math.tan(math.radians(hfov_after) / 2)


def hfov_after_factor(hfov: float, factor: float) -> float:
    """The horizontal FOV after scaling the image by `factor` (inverse of `focal_ratio`)."""
    return math.degrees(2 * math.atan(math.tan(math.radians(hfov) / 2) / factor))


def rate_for_byte(speed: int, model: DomeModelConfig, *, tilt: bool = False) -> float:
    """Signed angular rate (deg/s) of a signed Pelco speed under the dome model."""
    s = min(abs(int(speed)), PELCO_MAX_SPEED)
    if s == 0:
        return 0.0
    fraction = (s - 1) / (PELCO_MAX_SPEED - 1)
    if model.speed_curve == "linear":
        rate = model.speed_min + (model.speed_max - model.speed_min) * fraction
    else:
        rate = model.speed_min * (model.speed_max / model.speed_min) ** fraction
    if tilt:
        rate = min(rate, model.tilt_speed_max)
    return math.copysign(rate, speed)


def byte_for_rate(rate: float, model: DomeModelConfig, *, max_speed: int = PELCO_MAX_SPEED) -> int:
    """The signed Pelco speed whose rate is nearest `rate` (deg/s); 0 only for rate 0.

    Inverse of `rate_for_byte`; any non-zero rate gives at least speed 1, so the dome moves.
    """
    if rate == 0 or not math.isfinite(rate):
        return 0
    magnitude = abs(rate)
    if model.speed_curve == "linear":
        fraction = (magnitude - model.speed_min) / (model.speed_max - model.speed_min)
    else:
        fraction = math.log(magnitude / model.speed_min) / math.log(
            model.speed_max / model.speed_min
        )
    s = 1 + round(fraction * (PELCO_MAX_SPEED - 1))
    s = max(1, min(max_speed, s))
    return s if rate > 0 else -s


class DomeEstimate:
    """Dead-reckoned dome pose from the commands sent (pan/tilt speeds, zoom direction).

    It remembers the last `_HISTORY` commands with the pose each started from, so the pose
    at a past time (a frame's capture time, older than the commands sent since) is exact
    too: `pose_at`."""

    def __init__(
        self, model: DomeModelConfig, zoom_log_rate: float, start: Pose, time: float = 0.0
    ) -> None:
        self.model = model
        self.zoom_log_rate = zoom_log_rate
        self.pose = start
        self.time = time
        self._motion = (0, 0, 0)  # pan speed, tilt speed, zoom in force
        self._history: deque[tuple[float, Pose, tuple[int, int, int]]] = deque(maxlen=_HISTORY)
        self._remember()

    def _remember(self) -> None:
        self._history.append((self.time, self.pose, self._motion))

    def command(
        self, pan_speed: int, tilt_speed: int, zoom: int, time: float | None = None
    ) -> None:
        """The motion in force from `time` on (Pelco signed speeds; zoom -1 out, 0, +1 in).

        The estimate is first advanced to `time` under the motion it replaces (None: it
        starts at the estimate's own time, to which the caller has advanced it)."""
        if time is not None:
            self.advance_to(time)
        self._motion = (pan_speed, tilt_speed, zoom)
        self._remember()

    def reset(self, pose: Pose, time: float | None = None) -> None:
        """Replace the estimate with a known pose (e.g. one reported with a frame)."""
        self.pose = pose
        if time is not None:
            self.time = time
        self._history.clear()
        self._remember()

    def advance_to(self, time: float) -> Pose:
        """`advance` to an absolute time; earlier times change nothing."""
        if time > self.time:
            self.advance(time - self.time)
        return self.pose

    def advance(self, dt: float) -> Pose:
        """Integrate the motion in force over `dt` seconds; returns the new estimate."""
        if dt <= 0:
            return self.pose
        self.time += dt
        self.pose = self._integrate(self.pose, self._motion, dt)
        return self.pose

    def pose_at(self, time: float) -> Pose:
        """The pose at `time`: advanced to it if it is later, else recalled from the
        commands remembered (the oldest remembered pose for a time before them all)."""
        if time >= self.time:
            return self.advance_to(time)
        for started, pose, motion in reversed(self._history):
            if started <= time:
                return self._integrate(pose, motion, time - started)
        return self._history[0][1]

    def _integrate(self, pose: Pose, motion: tuple[int, int, int], dt: float) -> Pose:
        pan_speed, tilt_speed, zoom = motion
        pan = pose.pan + rate_for_byte(pan_speed, self.model) * dt
        tilt = pose.tilt + rate_for_byte(tilt_speed, self.model, tilt=True) * dt
        tilt = min(max(tilt, self.model.tilt_min), self.model.tilt_max)
        hfov = pose.hfov
        if zoom:
            hfov = hfov_after_factor(hfov, math.exp(zoom * self.zoom_log_rate * dt))
            # the lens stops at its ends; an estimate that went on would rescale the
            # tracker's box every frame for a zoom that is not happening (the real-time
            # soak's boxes shrank to 0.1 px while the dome, at its widest, was "widening")
            hfov = min(max(hfov, self.model.hfov_tele), self.model.hfov_wide)
        return Pose(pan, tilt, hfov)
