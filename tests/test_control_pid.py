"""PID: step response on a simulated plant, derivative on measurement, anti-windup, seed map."""

from __future__ import annotations

import math

import pytest

from ptzd.control.pid import Pid, PidGains, output_limit_for, pelco_speed

SEED = PidGains(kp=0.9, ki=0.1, kd=0.15)


def _closed_loop(pid: Pid, error0: float, plant_gain: float, dt: float, steps: int) -> list[float]:
    """A pan axis: the camera turns at plant_gain * C_out, shrinking the target's offset."""
    error = error0
    trace = []
    for _ in range(steps):
        c_out = pid.update(error, dt)
        error -= plant_gain * c_out * dt
        trace.append(error)
    return trace


def test_step_response_settles_without_large_overshoot() -> None:
    pid = Pid(SEED, output_limit=500.0, derivative_tau_s=0.05)
    trace = _closed_loop(pid, error0=200.0, plant_gain=2.0, dt=0.05, steps=400)
    assert abs(trace[-1]) < 3.0  # settled on the centre (PI on an integrating plant: slow tail)
    assert min(trace) > -0.1 * 200.0  # less than 10 % overshoot
    rise = next(i for i, e in enumerate(trace) if e < 20.0)
    assert rise * 0.05 < 2.0  # within 10 % of the centre in under 2 s


def test_proportional_kick_and_integral_accumulation() -> None:
    pid = Pid(PidGains(0.9, 0.1, 0.0))
    assert pid.update(100.0, 0.0) == pytest.approx(90.0)  # P only: no time has passed
    assert pid.update(100.0, 1.0) == pytest.approx(90.0 + 0.1 * 100.0)
    assert pid.update(100.0, 1.0) == pytest.approx(90.0 + 0.1 * 200.0)


def test_derivative_is_on_the_measurement_and_filtered() -> None:
    pid = Pid(PidGains(0.0, 0.0, 1.0), derivative_tau_s=0.0)
    pid.update(0.0, 0.1)
    pid.setpoint = 50.0  # moving the setpoint gives no derivative kick
    assert pid.update(0.0, 0.1) == pytest.approx(0.0)
    assert pid.update(1.0, 0.1) == pytest.approx(10.0)  # d(measurement)/dt = 10/s

    filtered = Pid(PidGains(0.0, 0.0, 1.0), derivative_tau_s=0.2)
    filtered.update(0.0, 0.1)
    first = filtered.update(1.0, 0.1)
    assert 0 < first < 10.0  # the low-pass softens a measurement jump
    assert first == pytest.approx(10.0 * 0.1 / 0.3)


def test_anti_windup_stops_integrating_in_saturation() -> None:
    limit = 50.0
    pid = Pid(PidGains(0.9, 0.1, 0.0), output_limit=limit)
    for _ in range(1000):  # 100 s pinned against the limit
        assert pid.update(200.0, 0.1) == limit
    # Without anti-windup the integral would be 200 * 100 = 20000; it did not grow.
    assert pid.integral < 1.0
    # ... so the output follows the error's sign change at once instead of after ~minutes.
    assert pid.update(-30.0, 0.1) < 0


def test_integral_limit_bounds_the_integral() -> None:
    pid = Pid(PidGains(0.0, 1.0, 0.0), integral_limit=5.0)
    for _ in range(100):
        pid.update(1.0, 1.0)
    assert pid.integral == 5.0


def test_seed_speed_mapping_eqs_28_to_31() -> None:
    assert pelco_speed(100.0, offset=12, max_speed=63) == 22  # 100 * 0.1 + 12
    assert pelco_speed(-100.0, offset=12, max_speed=63) == -22  # offset follows the sign
    assert pelco_speed(0.0, offset=6, max_speed=63) == 6  # C_out >= 0 takes +offset
    assert pelco_speed(10_000.0, offset=12, max_speed=63) == 63  # clamped to the Pelco range
    assert pelco_speed(-10_000.0, offset=12, max_speed=40) == -40
    assert output_limit_for(12, 63) == pytest.approx(510.0)


def test_rejects_non_finite_measurements() -> None:
    with pytest.raises(ValueError):
        Pid(SEED).update(math.nan, 0.1)
