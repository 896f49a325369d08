"""Configuration of person detection (`[detector]`, `[detector.bgcode]`, `[detector.hog]`).

Kept free of numpy/cv2 imports: `ptzd.config` loads it for every command.
"""

from __future__ import annotations

from typing import Literal, Self

from pydantic import Field, model_validator

from ptzd.schema import StrictModel


class BgCodeConfig(StrictModel):
    """Seed-002 detector: running-average background (eqs. 1-3) and codebook matching (4-5)."""

    alpha: float = Field(default=0.9, gt=0.0, lt=1.0)
    absorb_alpha: float = Field(default=0.995, gt=0.0, le=1.0)
    threshold: int = Field(default=25, ge=1, le=255)
    dilate_px: int = Field(default=2, ge=0, le=20)
    min_area: int = Field(default=120, ge=1, le=1_000_000)
    min_height: int = Field(default=30, ge=8, le=4000)
    warmup_frames: int = Field(default=10, ge=1, le=10_000)
    static_frames: int = Field(default=15, ge=1, le=100_000)
    max_foreground_fraction: float = Field(default=0.4, gt=0.0, le=1.0)
    max_fill: float = Field(default=0.97, gt=0.0, le=1.0)
    aspect_min: float = Field(default=1.4, gt=0.0, le=20.0)
    aspect_max: float = Field(default=5.0, gt=0.0, le=20.0)
    reject_border: bool = True
    codebook: str = ""
    distortion_threshold: float | None = Field(default=None, gt=0.0, le=1000.0)

    @model_validator(mode="after")
    def _consistent(self) -> Self:
        if self.aspect_min >= self.aspect_max:
            raise ValueError(
                f"aspect_min ({self.aspect_min}) must be below aspect_max ({self.aspect_max})"
            )
        if self.absorb_alpha < self.alpha:
            raise ValueError(
                f"absorb_alpha ({self.absorb_alpha}) must be >= alpha ({self.alpha}): pixels "
                "under the active mask are updated more slowly than the rest, never faster"
            )
        return self


class HogConfig(StrictModel):
    """OpenCV's HOG people detector (Dalal-Triggs weights shipped inside OpenCV 4.x)."""

    resize: float = Field(default=1.0, ge=0.25, le=4.0)
    hit_threshold: float = Field(default=0.0, ge=-5.0, le=10.0)
    win_stride: int = Field(default=8, ge=1, le=64)
    scale_step: float = Field(default=1.05, gt=1.0, le=2.0)
    min_score: float = Field(default=0.5, ge=0.0, le=1.0)


class DetectorConfig(StrictModel):
    """Which detector finds people, and what to do while the camera moves."""

    kind: Literal["bgcode", "hog"] = "bgcode"
    when_moving: Literal["wait", "hog"] = "wait"
    bgcode: BgCodeConfig = BgCodeConfig()
    hog: HogConfig = HogConfig()
