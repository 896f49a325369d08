"""Configuration of the simulated dome (`[sim]`).

Defaults describe a Pelco Spectra-like dome: 0.1..80 deg/s over speed bytes 1..63, turbo
150 deg/s, tilt at most 40 deg/s, 20x optical zoom from 60 degrees, wide to tele in ~4 s.
"""

from __future__ import annotations

import math
from typing import Literal

from pydantic import Field, model_validator

from ptzd.schema import StrictModel


class SimConfig(StrictModel):
    """Geometry and dynamics of the simulated dome."""

    # geometry
    wide_hfov: float = Field(default=90.0, gt=1.0, lt=179.0)
    view_width: int = Field(default=640, ge=16, le=7680)
    view_height: int = Field(default=480, ge=16, le=4320)
    fps: float | None = Field(default=None, gt=0.0, le=240.0)

    # serial side
    address: int = Field(default=1, ge=1, le=255)
    baudrate: int = Field(default=4800, ge=300, le=115200)
    latency_s: float = Field(default=0.05, ge=0.0, le=2.0)

    # pan / tilt
    speed_curve: Literal["exponential", "linear"] = "exponential"
    speed_min: float = Field(default=0.1, gt=0.0, le=1000.0)
    speed_max: float = Field(default=80.0, gt=0.0, le=1000.0)
    turbo_speed: float = Field(default=150.0, gt=0.0, le=1000.0)
    tilt_speed_max: float = Field(default=40.0, gt=0.0, le=1000.0)
    acceleration: float = Field(default=300.0, gt=0.0, le=100000.0)
    pan_endless: bool = True
    pan_min: float = Field(default=-180.0, ge=-360.0, le=360.0)
    pan_max: float = Field(default=180.0, ge=-360.0, le=360.0)
    tilt_min: float = Field(default=-90.0, ge=-90.0, le=90.0)
    tilt_max: float = Field(default=90.0, ge=-90.0, le=90.0)
    home_pan: float = Field(default=0.0, ge=-360.0, le=360.0)
    home_tilt: float = Field(default=0.0, ge=-90.0, le=90.0)
    proportional_speed: bool = False
    preset_speed: float = Field(default=250.0, gt=0.0, le=1000.0)

    # zoom
    zoom_hfov_wide: float = Field(default=60.0, gt=0.1, lt=179.0)
    zoom_ratio: float = Field(default=20.0, ge=1.0, le=100.0)
    zoom_travel_s: float = Field(default=4.0, gt=0.0, le=120.0)
    zoom_speed: int = Field(default=3, ge=0, le=3)

    # MJPEG stream
    jpeg_quality: int = Field(default=85, ge=10, le=100)
    # in-process (`ptzd sim`): JPEG-code every frame at `jpeg_quality` before the daemon
    # sees it, as the MJPEG stream (and `ptzd soak`) delivers it. camera.jsonl is unchanged:
    # the pose rendered; only the daemon's picture is compressed
    compress_frames: bool = False
    # in-process (`ptzd sim`): whether the daemon gets each frame's pose with it, as from a
    # dome that reports its position; false: as from a Pelco-P dome that reports nothing,
    # the daemon dead-reckons the pose from its commands (capture.latency_s applies)
    report_pose: bool = True
    # in-process (`ptzd sim` with a target): the dome's FOV at the start, still pointed at
    # the target (clamped to the lens); None: the FOV that makes the target a third of the
    # view high. The soak's dome starts at the widest, its walkers a ninth of the view high.
    start_hfov: float | None = Field(default=None, gt=0.1, lt=179.0)
    # in-process (`ptzd sim` with a target): the dome's pan and tilt at the start (degrees);
    # None: pointed at the target. With start_hfov, a soak's selection is played again
    # from the pose the soak's dome had (docs/reliability.md).
    start_pan: float | None = Field(default=None, ge=-360.0, le=360.0)
    start_tilt: float | None = Field(default=None, ge=-90.0, le=90.0)
    # a day/night dome going to night mode (IR-cut filter out): from this many seconds
    # after the start every view is grey, in three equal channels as a decoder gives it
    # (the wide video's luma: no IR illuminator, no near-infrared reflectance). None: day
    night_after_s: float | None = Field(default=None, ge=0.0, le=1e7)

    @model_validator(mode="after")
    def _check_ranges(self) -> SimConfig:
        if self.speed_min >= self.speed_max:
            raise ValueError(
                f"speed_min ({self.speed_min}) must be below speed_max ({self.speed_max})"
            )
        if self.tilt_min >= self.tilt_max:
            raise ValueError(f"tilt_min ({self.tilt_min}) must be below tilt_max ({self.tilt_max})")
        if not self.tilt_min <= self.home_tilt <= self.tilt_max:
            raise ValueError(
                f"home_tilt ({self.home_tilt}) must lie within tilt_min..tilt_max "
                f"({self.tilt_min}..{self.tilt_max})"
            )
        if not self.pan_endless:
            if self.pan_min >= self.pan_max:
                raise ValueError(
                    f"pan_min ({self.pan_min}) must be below pan_max ({self.pan_max}) "
                    "when pan_endless is false"
                )
            if not self.pan_min <= self.home_pan <= self.pan_max:
                raise ValueError(
                    f"home_pan ({self.home_pan}) must lie within pan_min..pan_max "
                    f"({self.pan_min}..{self.pan_max})"
                )
        if self.zoom_hfov_tele < 0.05:
            raise ValueError(
                f"zoom_hfov_wide {self.zoom_hfov_wide} with zoom_ratio {self.zoom_ratio} "
                f"gives a tele FOV of {self.zoom_hfov_tele:.4f} degrees, below 0.05"
            )
        return self

    @property
    def zoom_hfov_tele(self) -> float:
        """Horizontal FOV at full zoom: the focal length is `zoom_ratio` times the widest."""
        half = math.radians(self.zoom_hfov_wide) / 2.0
        return math.degrees(2.0 * math.atan(math.tan(half) / self.zoom_ratio))
