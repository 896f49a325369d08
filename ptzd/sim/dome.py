"""Dynamics of the simulated dome: pure, clock-injected, exact between commands.

`Dome.command(cmd, t)` takes a decoded Pelco command that finished arriving at time `t`; it
takes effect `latency_s` later. `Dome.advance_to(t)` moves the dome to time `t`. Motion is
integrated analytically (piecewise constant acceleration), so the pose at a time does not
depend on how often it is asked for: a run is the same whatever the frame rate.

Units: degrees, seconds. Pan + is right, tilt + is up (the camera model's convention).
Zoom position `zoom` runs from 0 (widest, `zoom_hfov_wide`) to 1 (full `zoom_ratio`); the
focal length is `f_wide * zoom_ratio ** zoom`, so zoom moves log-linearly in focal length.

Pelco-D absolute positions and position replies use these units (the Spectra convention):
pan in hundredths of a degree 0..35999 clockwise (right) from pan 0; tilt in hundredths of a
degree, 0 = level, positive = below the horizon, angles above it wrap to 36000 - x; zoom as
`magnification / zoom_ratio * 65535`.
"""

from __future__ import annotations

import heapq
import math
from dataclasses import dataclass, field

from ptzd.pelco.codec import (
    AbsolutePosition,
    Axis,
    Command,
    Motion,
    PositionQuery,
    PositionReply,
    Preset,
    PresetAction,
    ZoomSpeed,
)
from ptzd.sim.camera_model import Pose
from ptzd.sim.config import SimConfig

TURBO = 64
PAN_COUNTS = 36000
ZOOM_COUNTS = 65535


def speed_from_byte(speed: int, config: SimConfig) -> float:
    """Pan speed in deg/s for a Pelco speed byte 0..63 (64 = turbo) under the configured curve.

    Exponential (default): v = speed_min * (speed_max / speed_min) ** ((s - 1) / 62), so
    0.1 * 800 ** ((s - 1) / 62) = 0.1..80 deg/s; linear: speed_min..speed_max evenly.
    """
    s = abs(int(speed))
    if s == 0:
        return 0.0
    if s >= TURBO:
        return config.turbo_speed
    s = min(s, 63)
    fraction = (s - 1) / 62.0
    if config.speed_curve == "linear":
        return config.speed_min + (config.speed_max - config.speed_min) * fraction
    return float(config.speed_min * (config.speed_max / config.speed_min) ** fraction)


def wrap_degrees(angle: float) -> float:
    """`angle` wrapped to (-180, 180]."""
    wrapped = math.fmod(angle, 360.0)
    if wrapped <= -180.0:
        wrapped += 360.0
    elif wrapped > 180.0:
        wrapped -= 360.0
    return wrapped


@dataclass
class _Axis:
    """One rotation axis: position, velocity, and what it is trying to do."""

    position: float
    velocity: float = 0.0
    target_velocity: float = 0.0
    goal: float | None = None  # a position to travel to at `goal_speed` (preset / absolute)
    goal_speed: float = 0.0

    def integrate(self, dt: float, acceleration: float) -> None:
        if self.goal is not None:
            self.velocity = 0.0
            distance = self.goal - self.position
            step = self.goal_speed * dt
            if abs(distance) <= step:
                self.position = self.goal
                self.goal = None
            else:
                self.position += math.copysign(step, distance)
            return
        dv = self.target_velocity - self.velocity
        ramp = min(dt, abs(dv) / acceleration)
        a = math.copysign(acceleration, dv)
        self.position += self.velocity * ramp + 0.5 * a * ramp * ramp
        if ramp < dt or ramp == abs(dv) / acceleration:
            self.velocity = self.target_velocity
        else:
            self.velocity += a * ramp
        self.position += self.velocity * (dt - ramp)


@dataclass(frozen=True, slots=True)
class PresetPose:
    pan: float
    tilt: float
    zoom: float


@dataclass
class DomeCounters:
    commands: int = 0
    unsupported: int = 0  # decoded commands the dome does not act on (focus, aux, ...)
    unknown_presets: int = 0  # goto / clear of a preset that was never set
    queries: int = 0


@dataclass
class _Pending:
    when: float
    order: int
    command: Command = field(compare=False)

    def __lt__(self, other: _Pending) -> bool:
        return (self.when, self.order) < (other.when, other.order)


class Dome:
    """A pan-tilt-zoom dome obeying Pelco commands, advanced explicitly in time."""

    def __init__(
        self,
        config: SimConfig,
        *,
        start_time: float = 0.0,
        pan: float | None = None,
        tilt: float | None = None,
        zoom: float = 0.0,
    ) -> None:
        self.config = config
        self.time = float(start_time)
        self._pan = _Axis(config.home_pan if pan is None else float(pan))
        self._tilt = _Axis(config.home_tilt if tilt is None else float(tilt))
        self._zoom = min(1.0, max(0.0, float(zoom)))
        self._zoom_direction = 0
        self._zoom_goal: float | None = None
        self._zoom_speed = config.zoom_speed
        self._pending: list[_Pending] = []
        self._order = 0
        self.presets: dict[int, PresetPose] = {}
        self.counters = DomeCounters()
        self._limit_pan()
        self._limit_tilt()

    # --- state ---------------------------------------------------------------------------

    @property
    def pan(self) -> float:
        """Pan angle in degrees, in (-180, 180] when pan is endless."""
        if self.config.pan_endless:
            return wrap_degrees(self._pan.position)
        return self._pan.position

    @property
    def tilt(self) -> float:
        return self._tilt.position

    @property
    def zoom(self) -> float:
        """Zoom position, 0 (wide) .. 1 (tele)."""
        return self._zoom

    @property
    def magnification(self) -> float:
        return float(self.config.zoom_ratio**self._zoom)

    @property
    def hfov(self) -> float:
        half = math.radians(self.config.zoom_hfov_wide) / 2.0
        return math.degrees(2.0 * math.atan(math.tan(half) / self.magnification))

    @property
    def pose(self) -> Pose:
        return Pose(self.pan, self.tilt, self.hfov)

    @property
    def moving(self) -> bool:
        return bool(
            self._pan.velocity
            or self._pan.target_velocity
            or self._pan.goal is not None
            or self._tilt.velocity
            or self._tilt.target_velocity
            or self._tilt.goal is not None
            or self._zoom_direction
            or self._zoom_goal is not None
        )

    def zoom_rate(self, speed: int | None = None) -> float:
        """Zoom position change per second at Pelco zoom speed 0..3 (3 = `zoom_travel_s`)."""
        s = self._zoom_speed if speed is None else speed
        return (s + 1) / 4.0 / self.config.zoom_travel_s

    # --- commands ------------------------------------------------------------------------

    def command(self, command: Command, t: float) -> PositionReply | None:
        """A command that finished arriving at `t`. Queries are answered at once, others
        take effect `latency_s` later. Returns the reply to send back, if any."""
        self.counters.commands += 1
        self.advance_to(t)
        if isinstance(command, PositionQuery):
            self.counters.queries += 1
            return self.position_reply(command.axis)
        heapq.heappush(self._pending, _Pending(t + self.config.latency_s, self._order, command))
        self._order += 1
        return None

    def position_reply(self, axis: Axis) -> PositionReply:
        if axis == Axis.PAN:
            value = round(self.pan * 100.0) % PAN_COUNTS
        elif axis == Axis.TILT:
            value = round(-self.tilt * 100.0) % PAN_COUNTS
        else:
            value = round(self.magnification / self.config.zoom_ratio * ZOOM_COUNTS)
        return PositionReply(axis=axis, value=int(value))

    def home(self, t: float) -> None:
        """Travel to (home_pan, home_tilt) at the preset speed and zoom fully out."""
        self.advance_to(t)
        self._goto(PresetPose(self.config.home_pan, self.config.home_tilt, 0.0))

    def _apply(self, command: Command) -> None:
        if isinstance(command, Motion):
            self._apply_motion(command)
        elif isinstance(command, Preset):
            self._apply_preset(command)
        elif isinstance(command, ZoomSpeed):
            self._zoom_speed = min(3, max(0, command.speed))
        elif isinstance(command, AbsolutePosition):
            self._apply_absolute(command)
        else:
            self.counters.unsupported += 1

    def _apply_motion(self, motion: Motion) -> None:
        scale = 1.0 / self.magnification if self.config.proportional_speed else 1.0
        pan_speed = speed_from_byte(motion.pan, self.config) * scale
        tilt_speed = min(
            speed_from_byte(min(abs(motion.tilt), 63), self.config), self.config.tilt_speed_max
        )
        tilt_speed *= scale
        self._pan.goal = self._tilt.goal = self._zoom_goal = None
        self._pan.target_velocity = math.copysign(pan_speed, motion.pan) if motion.pan else 0.0
        self._tilt.target_velocity = math.copysign(tilt_speed, motion.tilt) if motion.tilt else 0.0
        self._zoom_direction = int(motion.zoom)

    def _apply_preset(self, preset: Preset) -> None:
        if preset.action == PresetAction.SET:
            self.presets[preset.number] = PresetPose(self.pan, self.tilt, self._zoom)
        elif preset.action == PresetAction.CLEAR:
            if self.presets.pop(preset.number, None) is None:
                self.counters.unknown_presets += 1
        else:
            target = self.presets.get(preset.number)
            if target is None:
                self.counters.unknown_presets += 1
                return
            self._goto(target)

    def _apply_absolute(self, command: AbsolutePosition) -> None:
        if command.axis == Axis.PAN:
            pan = wrap_degrees((command.value % PAN_COUNTS) / 100.0)
            self._travel(self._pan, pan, is_pan=True)
        elif command.axis == Axis.TILT:
            tilt = wrap_degrees(-(command.value % PAN_COUNTS) / 100.0)
            self._travel(self._tilt, min(self.config.tilt_max, max(self.config.tilt_min, tilt)))
        else:
            magnification = max(1.0, command.value / ZOOM_COUNTS * self.config.zoom_ratio)
            self._zoom_direction = 0
            self._zoom_goal = min(1.0, math.log(magnification) / math.log(self.config.zoom_ratio))

    def _goto(self, target: PresetPose) -> None:
        self._travel(self._pan, target.pan, is_pan=True)
        self._travel(self._tilt, target.tilt)
        self._zoom_direction = 0
        self._zoom_goal = target.zoom

    def _travel(self, axis: _Axis, goal: float, *, is_pan: bool = False) -> None:
        if is_pan and self.config.pan_endless:
            goal = axis.position + wrap_degrees(goal - axis.position)  # the short way round
        elif is_pan:
            goal = min(self.config.pan_max, max(self.config.pan_min, goal))
        axis.goal = goal
        axis.goal_speed = self.config.preset_speed
        axis.target_velocity = 0.0

    # --- time ----------------------------------------------------------------------------

    def advance_to(self, t: float) -> None:
        """Move the dome to time `t`, applying every command due by then at its own time.

        Asking for a time before the dome's current time changes nothing (the past is done).
        """
        while self._pending and self._pending[0].when <= t:
            due = heapq.heappop(self._pending)
            self._integrate(due.when - self.time)
            self._apply(due.command)
        self._integrate(t - self.time)

    def _integrate(self, dt: float) -> None:
        if dt <= 0.0:
            return
        self.time += dt
        accel = self.config.acceleration
        self._pan.integrate(dt, accel)
        self._tilt.integrate(dt, accel)
        self._limit_pan()
        self._limit_tilt()
        if self._zoom_goal is not None:
            step = self.zoom_rate(3) * dt
            distance = self._zoom_goal - self._zoom
            if abs(distance) <= step:
                self._zoom, self._zoom_goal = self._zoom_goal, None
            else:
                self._zoom += math.copysign(step, distance)
        elif self._zoom_direction:
            self._zoom += self._zoom_direction * self.zoom_rate() * dt
        self._zoom = min(1.0, max(0.0, self._zoom))

    def _limit_pan(self) -> None:
        axis = self._pan
        if self.config.pan_endless:
            if axis.goal is None:
                axis.position = wrap_degrees(axis.position)
            return
        _clamp(axis, self.config.pan_min, self.config.pan_max)

    def _limit_tilt(self) -> None:
        _clamp(self._tilt, self.config.tilt_min, self.config.tilt_max)


def _clamp(axis: _Axis, low: float, high: float) -> None:
    if axis.position < low or axis.position > high:
        axis.position = min(high, max(low, axis.position))
        axis.velocity = 0.0  # at the mechanical stop
