"""Configuration of target acquisition and management (`[acquisition]`).

Kept free of numpy/cv2 imports: `ptzd.config` loads it for every command.
"""

from __future__ import annotations

from typing import Literal, Self

from pydantic import Field, model_validator

from ptzd.schema import StrictModel


class AcquisitionConfig(StrictModel):
    """How a target is chosen, confirmed, kept, dropped and given up."""

    # Run the detector and this state machine in the daemon (off: only selected targets)
    enabled: bool = True
    policy: Literal["largest", "center", "zone"] = "largest"
    zone: tuple[float, float, float, float] | None = None
    persist_frames: int = Field(default=3, ge=1, le=100)
    associate_iou: float = Field(default=0.3, gt=0.0, le=1.0)
    max_candidate_misses: int = Field(default=2, ge=0, le=100)
    min_switch_s: float = Field(default=5.0, ge=0.0, le=3600.0)
    switch_margin: float = Field(default=1.5, ge=1.0, le=100.0)
    revalidate_s: float = Field(default=1.0, gt=0.0, le=600.0)
    confirm_iou: float = Field(default=0.2, gt=0.0, le=1.0)
    static_s: float = Field(default=10.0, gt=0.0, le=3600.0)
    static_px: float = Field(default=4.0, ge=0.0, le=1000.0)
    # ... or this share of the box height, if more: a tracker's box on a still object
    # jitters by more than a few pixels when the object is big in the view
    static_fraction: float = Field(default=0.1, ge=0.0, le=1.0)
    ignore_static_s: float = Field(default=60.0, ge=0.0, le=86400.0)
    occluded_timeout_s: float = Field(default=2.0, gt=0.0, le=600.0)
    lost_timeout_s: float = Field(default=5.0, gt=0.0, le=3600.0)
    # a re-identifying detection shorter than this share of the lost box is taken as the
    # visible part of the target (see Acquirer._whole)
    partial_height: float = Field(default=0.8, ge=0.0, le=1.0)
    return_home: bool = True
    home_settle_s: float = Field(default=3.0, ge=0.0, le=600.0)
    # searching this long without a lock, after the dome followed someone away from home,
    # goes home too (0 = never)
    search_timeout_s: float = Field(default=60.0, ge=0.0, le=86400.0)

    @model_validator(mode="after")
    def _zone(self) -> Self:
        if self.policy == "zone" and self.zone is None:
            raise ValueError("policy 'zone' needs zone = [x0, y0, x1, y1]")
        if self.zone is not None:
            x0, y0, x1, y1 = self.zone
            if not (0.0 <= x0 < x1 <= 1.0 and 0.0 <= y0 < y1 <= 1.0):
                raise ValueError(
                    f"zone {list(self.zone)} must be [x0, y0, x1, y1] fractions of the frame "
                    "with 0 <= x0 < x1 <= 1 and 0 <= y0 < y1 <= 1"
                )
        return self
