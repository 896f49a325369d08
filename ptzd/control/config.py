"""Configuration of the control loop (`[control]` and its sub-tables).

Defaults follow seed 002 (Chang et al. 2020, sec. 3.3 and 4.2): Kp 0.9, Ki 0.1, Kd 0.15,
offset_pan 12, offset_tilt 6, rate_big 1.1, rate_small 0.9.
"""

from __future__ import annotations

from typing import Literal, Self

from pydantic import Field, model_validator

from ptzd.pelco.codec import MAX_SPEED as PELCO_MAX_SPEED  # 0x3F; turbo is never commanded
from ptzd.schema import StrictModel


class AxisConfig(StrictModel):
    """One PID axis (pan or tilt): gains, the seed's speed offset and output limits.

    The error is the target's offset from the view centre in pixels of a `reference_width`
    wide frame (the seed's 720 px), so the gains mean the same thing at every resolution.
    """

    kp: float = Field(default=0.9, ge=0.0, le=100.0)
    ki: float = Field(default=0.1, ge=0.0, le=100.0)
    kd: float = Field(default=0.15, ge=0.0, le=100.0)
    offset: int = Field(default=12, ge=0, le=PELCO_MAX_SPEED)
    max_speed: int = Field(default=PELCO_MAX_SPEED, ge=1, le=PELCO_MAX_SPEED)
    integral_limit: float = Field(default=200.0, gt=0.0, le=1e6)
    derivative_tau_s: float = Field(default=0.1, ge=0.0, le=5.0)

    @model_validator(mode="after")
    def _offset_below_max(self) -> Self:
        if self.offset > self.max_speed:
            raise ValueError(f"offset ({self.offset}) must not exceed max_speed ({self.max_speed})")
        return self


class RegionsConfig(StrictModel):
    """The 9-region field of view: a central stop region with hysteresis, per axis.

    Sizes are half-widths as a fraction of the half frame (0 = centre line, 1 = frame edge);
    the central cell of the 3x3 grid is 1/3.
    """

    stop_enter: float = Field(default=0.06, gt=0.0, lt=1.0)
    stop_leave: float = Field(default=0.16, gt=0.0, lt=1.0)

    @model_validator(mode="after")
    def _enter_inside_leave(self) -> Self:
        if self.stop_enter >= self.stop_leave:
            raise ValueError(
                f"stop_enter ({self.stop_enter}) must be smaller than stop_leave "
                f"({self.stop_leave}) or the stop region has no hysteresis"
            )
        return self


class ZoomConfig(StrictModel):
    """Zoom layers (seed eqs. 32-38) and the guards that stop zoom hunting."""

    enabled: bool = True
    size_measure: Literal["seed", "height"] = "height"
    target_height: float = Field(default=0.0, ge=0.0, le=0.95)
    rate_big: float = Field(default=1.1, gt=1.0, le=2.0)
    rate_small: float = Field(default=0.9, gt=0.3, lt=1.0)
    min_layer: int = Field(default=-10, ge=-100, le=0)
    max_layer: int = Field(default=10, ge=0, le=100)
    inside_margin: float = Field(default=0.15, ge=0.0, lt=0.5)
    center_radius: float = Field(default=0.34, gt=0.0, le=1.0)
    edge_margin: float = Field(default=0.05, ge=0.0, lt=0.5)
    slow_speed: float = Field(default=0.15, gt=0.0, le=10.0)
    fast_speed: float = Field(default=0.6, gt=0.0, le=10.0)
    confirm_s: float = Field(default=0.4, ge=0.0, le=30.0)
    min_dwell_s: float = Field(default=1.5, ge=0.0, le=60.0)
    # one second over the 10 s the target counts in: what the camera renders lags control
    reversal_guard_s: float = Field(default=11.0, ge=0.0, le=600.0)
    log_rate: float = Field(default=0.75, gt=0.01, le=20.0)
    min_step_s: float = Field(default=0.05, gt=0.0, le=5.0)
    max_step_s: float = Field(default=1.0, gt=0.0, le=10.0)
    # Beyond the seed: zoom in only on a track at least this confident (0: always; 0.8 as
    # feed-forward's gate). A half-hidden walker's box shrinks; zooming in on it spent the
    # reversal guard, and the zoom could not go out again while he walked up to the camera
    # (docs/control.md). Zooming out is never held back.
    in_min_confidence: float = Field(default=0.8, ge=0.0, le=1.0)
    # Beyond the seed: zoom in only on a box at least `in_min_height_share` of the tallest
    # the target has been (as an angle, so zooming does not change it) in the last
    # `in_height_window_s` seconds (0: off). A person does not lose a quarter of his height
    # in a few seconds; a tracker box that collapses onto his torso behind a lamp post does,
    # and a zoom in on it made him twice the desired size (synthetic:16, docs/control.md).
    in_height_window_s: float = Field(default=3.0, ge=0.0, le=60.0)
    in_min_height_share: float = Field(default=0.75, gt=0.0, le=1.0)
    # Beyond the seed: nor on a box more than (1 + `in_max_growth`) x the shortest it has
    # been in that window (0: off). A box growing back after a collapse is smaller than
    # the walker still, and a step in on it made him 1.3x the desired size; a walker
    # coming closer grows too, and needs no step in (synthetic:18, docs/control.md).
    in_max_growth: float = Field(default=0.2, ge=0.0, le=10.0)

    @model_validator(mode="after")
    def _consistent(self) -> Self:
        if self.slow_speed >= self.fast_speed:
            raise ValueError(
                f"slow_speed ({self.slow_speed}) must be below fast_speed ({self.fast_speed})"
            )
        if self.min_step_s > self.max_step_s:
            raise ValueError(
                f"min_step_s ({self.min_step_s}) must not exceed max_step_s ({self.max_step_s})"
            )
        return self


class LostConfig(StrictModel):
    """What the dome does once the target is lost: stop, hold, then go to a home preset."""

    follow_occluded: bool = True
    # Beyond the seed: for this long after the track goes LOST the dome keeps following the
    # tracker's coasting box before it stops (0: stop at once), by the box's position only
    # (no feed-forward: docs/daemon.md, "tenth pass"). A walker hidden behind a column for
    # longer than the tracker's occlusion limit walks on, and the tracker finds him again
    # a few frames later (synthetic:12, docs/control.md).
    follow_lost_s: float = Field(default=1.0, ge=0.0, le=60.0)
    hold_s: float = Field(default=5.0, ge=0.0, le=3600.0)
    home_preset: int = Field(default=0, ge=0, le=255)
    # without a home preset, "going home" zooms fully out for this long (so the detector can
    # find someone again rather than stare at whatever the dome was zoomed in on); 0 = stay
    widen_s: float = Field(default=5.0, ge=0.0, le=120.0)


class DomeModelConfig(StrictModel):
    """What the daemon believes about the dome's speed curve (defaults: a Spectra-like dome).

    Speed byte s (1..63) turns at `speed_min * (speed_max / speed_min) ** ((s - 1) / 62)` deg/s
    (exponential) or linearly from speed_min to speed_max; tilt is capped at tilt_speed_max.
    Used to turn the seed's speeds into angular rates and for ego-motion without a pose;
    the estimated pose stops at the lens's ends (`hfov_wide`, `hfov_tele`) and the tilt
    limits, as the dome does.
    """

    speed_curve: Literal["exponential", "linear"] = "exponential"
    speed_min: float = Field(default=0.1, gt=0.0, le=1000.0)
    speed_max: float = Field(default=80.0, gt=0.0, le=1000.0)
    tilt_speed_max: float = Field(default=40.0, gt=0.0, le=1000.0)
    hfov_wide: float = Field(default=60.0, gt=0.05, lt=179.0)
    hfov_tele: float = Field(default=3.0, gt=0.05, lt=179.0)
    tilt_min: float = Field(default=-90.0, ge=-90.0, le=90.0)
    tilt_max: float = Field(default=90.0, ge=-90.0, le=90.0)

    @model_validator(mode="after")
    def _min_below_max(self) -> Self:
        if self.speed_min >= self.speed_max:
            raise ValueError(
                f"speed_min ({self.speed_min}) must be below speed_max ({self.speed_max})"
            )
        if self.tilt_min >= self.tilt_max:
            raise ValueError(f"tilt_min ({self.tilt_min}) must be below tilt_max ({self.tilt_max})")
        if self.hfov_tele >= self.hfov_wide:
            raise ValueError(
                f"hfov_tele ({self.hfov_tele}) must be below hfov_wide ({self.hfov_wide})"
            )
        return self


class ControlConfig(StrictModel):
    """Control loop: rate, staleness limit, latency compensation and its controllers."""

    rate_hz: float = Field(default=20.0, gt=0.5, le=200.0)
    max_track_age_s: float = Field(default=0.5, gt=0.0, le=10.0)
    refresh_s: float = Field(default=1.0, gt=0.0, le=60.0)
    lead_s: float = Field(default=0.05, ge=0.0, le=2.0)
    # beyond the seed: turn with the target at its own angular rate (from the tracker's
    # ego-motion-free velocity), the PID only correcting the offset; 0 = the seed's pure PID
    feedforward: float = Field(default=1.0, ge=0.0, le=2.0)
    feedforward_min_deg_s: float = Field(default=0.3, ge=0.0, le=100.0)
    feedforward_dead_reckoned: bool = False  # also without a pose from the camera (see docs)
    feedforward_min_confidence: float = Field(default=0.8, ge=0.0, le=1.0)
    # ... except while OCCLUDED: the tracker then coasts on the velocity it learned from its
    # last confident frames, and the dome turns on with it (false: the PID alone follows the
    # coasting box, which stands in the stop band while the walker walks out of view)
    feedforward_while_occluded: bool = True
    reference_width: int = Field(default=720, ge=16, le=7680)
    reference_hfov: float = Field(default=60.0, gt=0.5, lt=179.0)
    linear_max_deg_s: float = Field(default=40.0, gt=0.0, le=1000.0)
    min_gain_scale: float = Field(default=0.1, gt=0.0, le=1.0)
    manual_speed: int = Field(default=20, ge=1, le=PELCO_MAX_SPEED)
    pan: AxisConfig = AxisConfig()
    tilt: AxisConfig = AxisConfig(offset=6)
    regions: RegionsConfig = RegionsConfig()
    zoom: ZoomConfig = ZoomConfig()
    lost: LostConfig = LostConfig()
    dome: DomeModelConfig = DomeModelConfig()

    @model_validator(mode="after")
    def _track_age_vs_rate(self) -> Self:
        if self.max_track_age_s < 1.0 / self.rate_hz:
            raise ValueError(
                f"max_track_age_s ({self.max_track_age_s}) is shorter than one control period "
                f"(1/rate_hz = {1.0 / self.rate_hz:.3g} s): every track would be stale"
            )
        if self.zoom.center_radius <= self.regions.stop_leave:
            raise ValueError(
                f"zoom.center_radius ({self.zoom.center_radius}) must exceed "
                f"regions.stop_leave ({self.regions.stop_leave})"
            )
        return self
