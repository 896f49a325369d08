"""`PtzController`: track in, Pelco command out. Pure; time is passed in.

Per update:
1. A missing or stale track (older than `max_track_age_s`) stops the dome.
2. LOST starts the lost policy: stop, hold `lost.hold_s`, then go to `lost.home_preset` once.
   OCCLUDED holds still (the tracker coasts; chasing a guess moves the camera off the scene).
3. TRACKING: the target is predicted forward by its age plus `lead_s` (latency compensation);
   its offset from the centre, normalised to the half frame, picks one of nine regions
   (hysteretic stop region); outside the stop band each axis runs its PID on the offset in
   pixels of a `reference_width` frame and maps C_out to the seed's speed (eqs. 28-31).
4. Beyond the seed, that speed is read as a fraction of a linear dome's range
   (`linear_max_deg_s` at full speed), scaled by the current FOV over `reference_hfov` (a pixel
   is a smaller angle when zoomed in), and turned into the real dome's speed byte through its
   speed curve (`DomeModelConfig`), so the loop behaves alike on linear and exponential domes
   and at every zoom.
   Feed-forward (beyond the seed): the target's own angular rate, from the tracker's
   velocity with the camera's motion removed, is added on each axis, inside the stop band
   too, so the PID only corrects the offset instead of chasing a walker stop-and-go.
5. Zoom: `ZoomController` decides steps; a step is a zoom pulse long enough to scale the image
   by the step's factor at the dome's zoom rate (`zoom.log_rate`).
"""

from __future__ import annotations

import math
from collections import deque
from dataclasses import dataclass

from ptzd.control.config import AxisConfig, ControlConfig
from ptzd.control.egomotion import byte_for_rate
from ptzd.control.pid import Pid, PidGains, output_limit_for, pelco_speed
from ptzd.control.regions import NineRegionFov, Region
from ptzd.control.zoom import Box, ZoomController, ZoomDirection, ZoomStep
from ptzd.pelco.codec import MAX_SPEED as PELCO_MAX_SPEED
from ptzd.pelco.codec import STOP, Motion, Preset, PresetAction, Zoom
from ptzd.sim.camera_model import focal_length
from ptzd.vision.tracking import TrackState

__all__ = ["STOP", "ControlDecision", "PtzController", "TrackInput"]

_WIDEN = Motion(zoom=Zoom.OUT)  # going "home" without a home preset


@dataclass(frozen=True)
class TrackInput:
    """What the controller needs from one tracker result (view pixels, seconds)."""

    box: Box
    velocity: tuple[float, float]  # px/s in the view
    state: TrackState
    confidence: float
    capture_time: float
    # whether the camera reported its pose with the frame (else it was dead-reckoned from the
    # commands sent, and the velocity's camera motion removed on that belief)
    pose_reported: bool = True


@dataclass(frozen=True)
class ControlDecision:
    """The command to be in force now, plus what led to it."""

    motion: Motion
    mode: str  # idle | stale | track | coast | hold | lost | home | widen
    preset: Preset | None = None
    zoom_step: ZoomStep | None = None
    region: Region | None = None
    track_time: float | None = None  # capture time of the track acted on
    predicted: tuple[float, float] | None = None


def _make_pid(cfg: AxisConfig) -> Pid:
    return Pid(
        PidGains(cfg.kp, cfg.ki, cfg.kd),
        # with offset == max_speed any output saturates; keep a tiny positive limit
        output_limit=max(output_limit_for(cfg.offset, cfg.max_speed), 1e-6),
        integral_limit=cfg.integral_limit,
        derivative_tau_s=cfg.derivative_tau_s,
    )


class PtzController:
    """Pan/tilt PIDs, nine-region FOV, zoom layers and the target-lost policy together."""

    def __init__(self, config: ControlConfig, frame_size: tuple[int, int]) -> None:
        self.config = config
        self.frame_size = frame_size
        self.pan_pid = _make_pid(config.pan)
        self.tilt_pid = _make_pid(config.tilt)
        self.regions = NineRegionFov(config.regions.stop_enter, config.regions.stop_leave)
        self.zoom = ZoomController(config.zoom)
        self._last_time: float | None = None
        self._zoom_until = -math.inf
        self._zoom_direction = Zoom.NONE
        self._lost_since: float | None = None
        self._went_home = False
        self._widen_until = -math.inf  # zooming fully out instead of a home preset
        # (capture time, box height / focal length) of recent confident tracks: zoom-free
        self._heights: deque[tuple[float, float]] = deque()

    @property
    def zoom_layer(self) -> int:
        return self.zoom.layer

    def acquire(self, box: Box) -> None:
        """A new target: its box sets the desired size; the loop starts from rest."""
        self.zoom.set_desired_from_box(box, self.frame_size[1])
        self._rest()
        self._heights.clear()
        self._lost_since = None
        self._went_home = False
        self._widen_until = -math.inf

    def _rest(self) -> None:
        self.pan_pid.reset()
        self.tilt_pid.reset()
        self.regions.reset()
        self.zoom.reset_guards()
        self._zoom_until = -math.inf
        self._zoom_direction = Zoom.NONE

    def gain_scale(self, hfov: float) -> float:
        """Angular-rate scale for the current FOV, within [min_gain_scale, 1]."""
        cfg = self.config
        return max(cfg.min_gain_scale, min(1.0, hfov / cfg.reference_hfov))

    def update(
        self, track: TrackInput | None, now: float, hfov: float, frame_time: float | None = None
    ) -> ControlDecision:
        """The command for time `now` given the latest track and the current horizontal FOV.

        `frame_time`: capture time of the newest frame the vision stage has seen, with or
        without a target in it (None: unknown)."""
        dt = 0.0 if self._last_time is None else max(0.0, now - self._last_time)
        self._last_time = now
        cfg = self.config
        widening = now < self._widen_until
        if track is None:
            self._rest()
            if frame_time is not None and now - frame_time > cfg.max_track_age_s:
                # no target and no fresh frames either: a stream that stalls while the dome
                # widens must not leave it zooming for the rest of widen_s
                return ControlDecision(STOP, "stale")
            return ControlDecision(_WIDEN if widening else STOP, "widen" if widening else "idle")
        if now - track.capture_time > cfg.max_track_age_s:
            self._rest()
            return ControlDecision(STOP, "stale", track_time=track.capture_time)
        if track.state == TrackState.LOST:
            if self._lost_since is None:
                self._lost_since = now
            lost_for = now - self._lost_since
            if cfg.lost.follow_occluded and lost_for < cfg.lost.follow_lost_s:
                return self._track(track, now, dt, hfov, zoom=False, mode="coast")
            return self._lost(now, lost_for, track.capture_time)
        self._lost_since = None
        self._went_home = False
        if track.state == TrackState.OCCLUDED:
            if not cfg.lost.follow_occluded:
                self._rest()
                return ControlDecision(STOP, "hold", track_time=track.capture_time)
            # follow the tracker's coasting prediction; never zoom on a guess
            return self._track(track, now, dt, hfov, zoom=False, mode="coast")
        return self._track(track, now, dt, hfov)

    def go_home(self, now: float) -> Preset | None:
        """The home preset to go to now, once per loss (None without one or if already sent).

        Without a home preset (and with `lost.widen_s`), going home at `now` means zooming
        fully out: the next `widen_s` seconds of updates without a track command zoom OUT."""
        home = self.config.lost.home_preset
        if self._went_home:
            return None
        if not home:
            if self.config.lost.widen_s > 0:
                self._went_home = True
                self._widen_until = now + self.config.lost.widen_s
                self.zoom.layer = 0
            return None
        self._went_home = True
        self.zoom.layer = 0
        return Preset(PresetAction.GOTO, home)

    def _lost(self, now: float, lost_for: float, track_time: float) -> ControlDecision:
        self._rest()
        if lost_for >= self.config.lost.hold_s and (preset := self.go_home(now)):
            return ControlDecision(STOP, "home", preset=preset, track_time=track_time)
        if now < self._widen_until:
            return ControlDecision(_WIDEN, "widen", track_time=track_time)
        return ControlDecision(STOP, "lost", track_time=track_time)

    def _track(
        self,
        track: TrackInput,
        now: float,
        dt: float,
        hfov: float,
        *,
        zoom: bool = True,
        mode: str = "track",
    ) -> ControlDecision:
        cfg = self.config
        width, height = self.frame_size
        lead = max(0.0, now - track.capture_time) + cfg.lead_s
        vx, vy = track.velocity
        box = track.box
        cx, cy = box.cx + vx * lead, box.cy + vy * lead
        ex = (cx - width / 2) / (width / 2)
        ey = (cy - height / 2) / (height / 2)
        region = self.regions.update(ex, ey)
        to_reference = cfg.reference_width / width
        scale = self.gain_scale(hfov)

        def axis(zone: int, offset_px: float, v_px_s: float, *, tilt: bool) -> int:
            feedforward = self._feedforward(v_px_s, hfov, track)
            return self._axis_speed(
                zone, offset_px * to_reference, dt, scale, tilt=tilt, feedforward=feedforward
            )

        pan = axis(region.column, cx - width / 2, vx, tilt=False)
        # image y grows downwards, tilt + is up: a target below the centre needs tilt < 0
        tilt = -axis(region.row, cy - height / 2, vy, tilt=True)

        step: ZoomStep | None = None
        if not zoom:
            self._zoom_until = -math.inf
            self._zoom_direction = Zoom.NONE
            self.zoom.reset_guards()
        elif now >= self._zoom_until:
            self._zoom_direction = Zoom.NONE
            speed = math.hypot(vx, vy) / width
            predicted_box = Box(box.x + vx * lead, box.y + vy * lead, box.w, box.h)
            dome = cfg.dome
            step = self.zoom.update(
                predicted_box,
                self.frame_size,
                speed,
                now,
                can_in=hfov > dome.hfov_tele * 1.01
                and track.confidence >= cfg.zoom.in_min_confidence
                and self._as_tall_as_lately(track, hfov),
                can_out=hfov < dome.hfov_wide * 0.99,
            )
            if step is not None:
                duration = abs(math.log(step.factor)) / cfg.zoom.log_rate
                duration = min(cfg.zoom.max_step_s, max(cfg.zoom.min_step_s, duration))
                self._zoom_until = now + duration
                self._zoom_direction = Zoom.IN if step.direction == ZoomDirection.IN else Zoom.OUT
        motion = Motion(pan=pan, tilt=tilt, zoom=self._zoom_direction)
        return ControlDecision(
            motion,
            mode,
            zoom_step=step,
            region=region,
            track_time=track.capture_time,
            predicted=(cx, cy),
        )

    def _as_tall_as_lately(self, track: TrackInput, hfov: float) -> bool:
        """Whether the box is at least `in_min_height_share` of the target's tallest in the
        last `in_height_window_s` (heights over the focal length: a zoom step leaves them
        be), and, with `in_max_growth`, at most (1 + it) x the shortest: steady enough to
        zoom in on. Without a window, always True. Called only for tracks confident enough
        to zoom in on, so only their heights are remembered."""
        zoom = self.config.zoom
        if zoom.in_height_window_s <= 0:
            return True
        height = track.box.h / focal_length(self.frame_size[0], hfov)
        heights = self._heights
        if not heights or heights[-1][0] < track.capture_time:
            heights.append((track.capture_time, height))
        while heights and heights[0][0] < track.capture_time - zoom.in_height_window_s:
            heights.popleft()
        tallest = max((h for _, h in heights), default=height)
        shortest = min((h for _, h in heights), default=height)
        growing = zoom.in_max_growth > 0 and height > (1 + zoom.in_max_growth) * shortest
        return height >= zoom.in_min_height_share * tallest and not growing

    def _feedforward(self, v_px_s: float, hfov: float, track: TrackInput) -> float:
        """The target's own angular rate (deg/s) from its image velocity, times the
        feed-forward gain; 0 below `feedforward_min_deg_s` (a standing person's jitter).

        Only with a reported pose, unless `feedforward_dead_reckoned`: the velocity has the
        camera's motion removed, and with a dead-reckoned pose that motion is what we
        commanded, not what happened. A dome that does not move (at an end stop, or the video
        is not from it) would make the target seem to run off with the camera, and
        feed-forward would chase that at ever higher speed."""
        cfg = self.config
        if cfg.feedforward <= 0 or not (track.pose_reported or cfg.feedforward_dead_reckoned):
            return 0.0
        # A LOST track followed for `follow_lost_s` is not coasting here: under the confidence
        # gate, as lost tracks are, it is followed by its position alone. Turning on with its
        # coast as well lost walkers out of view: closed-loop bench 105 -> 98/120 runs met
        # (docs/daemon.md, "tenth pass").
        coasting = track.state == TrackState.OCCLUDED and cfg.feedforward_while_occluded
        if track.confidence < cfg.feedforward_min_confidence and not coasting:
            return 0.0
        # degrees per pixel at the view centre: 1/f radians
        rate = math.degrees(v_px_s / focal_length(self.frame_size[0], hfov))
        if abs(rate) < cfg.feedforward_min_deg_s:
            return 0.0
        return cfg.feedforward * rate

    def _axis_speed(
        self,
        zone: int,
        error_px: float,
        dt: float,
        scale: float,
        *,
        tilt: bool,
        feedforward: float = 0.0,
    ) -> int:
        """Signed speed byte: the PID's correction (outside the stop band) plus the
        feed-forward rate that matches the target's own motion (also inside it)."""
        axis_cfg = self.config.tilt if tilt else self.config.pan
        pid = self.tilt_pid if tilt else self.pan_pid
        correction = 0.0
        if zone == 0:
            pid.reset()
        else:
            c_out = pid.update(error_px, dt)
            seed_speed = pelco_speed(c_out, offset=axis_cfg.offset, max_speed=axis_cfg.max_speed)
            # The PID (through its derivative) may briefly oppose the region's direction;
            # the region decides the direction, so that reads as "not yet": no correction.
            if seed_speed != 0 and (seed_speed > 0) == (zone > 0):
                correction = seed_speed / PELCO_MAX_SPEED * self.config.linear_max_deg_s * scale
        rate = correction + feedforward
        if correction and feedforward and (rate > 0) != (correction > 0):
            rate = 0.0  # a target moving back towards the centre: let it come
        return byte_for_rate(rate, self.config.dome, max_speed=axis_cfg.max_speed)
