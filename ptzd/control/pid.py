"""PID for one axis, and the seed's mapping of its output to a Pelco speed.

Seed 002 eqs. 28-31: `speed = C_out * 0.1 + offset`, the offset taking the sign of C_out.
The PID is direct-acting (error = measurement - setpoint; a target right of centre gives a
positive output, i.e. pan right), takes its derivative on the measurement through a
first-order low-pass filter (no kick when the setpoint moves, less pixel noise), and stops
integrating while the output is saturated in the direction of the error (anti-windup).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

SPEED_PER_OUTPUT = 0.1  # seed eqs. 28-29


@dataclass(frozen=True)
class PidGains:
    kp: float
    ki: float
    kd: float


class Pid:
    """A clock-injected PID: `update(measurement, dt)` returns the output C_out.

    `output_limit` bounds |C_out|; `integral_limit` bounds the accumulated error.
    `gain_scale` (per update) multiplies all three terms, e.g. to follow the field of view.
    """

    def __init__(
        self,
        gains: PidGains,
        *,
        setpoint: float = 0.0,
        output_limit: float = math.inf,
        integral_limit: float = math.inf,
        derivative_tau_s: float = 0.0,
    ) -> None:
        if output_limit <= 0 or integral_limit <= 0 or derivative_tau_s < 0:
            raise ValueError("limits must be positive and the filter constant non-negative")
        self.gains = gains
        self.setpoint = setpoint
        self.output_limit = output_limit
        self.integral_limit = integral_limit
        self.derivative_tau_s = derivative_tau_s
        self.integral = 0.0
        self.derivative = 0.0
        self._last_measurement: float | None = None
        self.last_output = 0.0

    def reset(self) -> None:
        """Forget the integral, the derivative filter and the last measurement."""
        self.integral = 0.0
        self.derivative = 0.0
        self._last_measurement = None
        self.last_output = 0.0

    def update(self, measurement: float, dt: float, *, gain_scale: float = 1.0) -> float:
        """Advance by `dt` seconds with a new measurement; returns the clamped output."""
        if not math.isfinite(measurement):
            raise ValueError(f"measurement must be finite, got {measurement!r}")
        if dt <= 0:
            # No time passed: nothing to integrate or differentiate; report the P+I+D as is.
            dt = 0.0
        error = measurement - self.setpoint
        g = self.gains
        if self._last_measurement is not None and dt > 0:
            raw = (measurement - self._last_measurement) / dt
            alpha = dt / (self.derivative_tau_s + dt)
            self.derivative += alpha * (raw - self.derivative)
        self._last_measurement = measurement

        candidate = self.integral + error * dt
        candidate = max(-self.integral_limit, min(self.integral_limit, candidate))
        unclamped = gain_scale * (g.kp * error + g.ki * candidate + g.kd * self.derivative)
        saturated = abs(unclamped) > self.output_limit
        # Anti-windup (conditional integration): keep the old integral when the output is
        # already saturated and integrating would push it further the same way.
        if not (saturated and math.copysign(1.0, unclamped) == math.copysign(1.0, error)):
            self.integral = candidate
        output = gain_scale * (g.kp * error + g.ki * self.integral + g.kd * self.derivative)
        output = max(-self.output_limit, min(self.output_limit, output))
        self.last_output = output
        return output


def output_limit_for(offset: int, max_speed: int) -> float:
    """The |C_out| at which the seed's speed mapping reaches `max_speed`."""
    return max(max_speed - offset, 0) / SPEED_PER_OUTPUT


def pelco_speed(c_out: float, *, offset: int, max_speed: int) -> int:
    """Seed eqs. 28-31: signed Pelco speed `C_out*0.1 ± offset`, clamped to ±max_speed.

    The offset follows the sign of C_out (C_out >= 0 takes +offset). The result is an
    integer speed in -max_speed..max_speed (max_speed <= 63; turbo is never produced).
    """
    signed_offset = offset if c_out >= 0 else -offset
    speed = c_out * SPEED_PER_OUTPUT + signed_offset
    speed = max(-float(max_speed), min(float(max_speed), speed))
    return round(speed)
