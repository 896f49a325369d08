"""Dome dynamics: speed curves, acceleration, latency, limits, zoom timing, presets, queries."""

from __future__ import annotations

import math

import pytest

from ptzd.config import validate_config
from ptzd.errors import ConfigError
from ptzd.pelco.codec import (
    AbsolutePosition,
    Axis,
    Motion,
    PositionQuery,
    Preset,
    PresetAction,
    Zoom,
    ZoomSpeed,
)
from ptzd.sim.config import SimConfig
from ptzd.sim.dome import Dome, speed_from_byte, wrap_degrees

EXPONENTIAL = SimConfig()
LINEAR = SimConfig(speed_curve="linear")


def test_speed_curves_match_the_documented_formulas() -> None:
    assert speed_from_byte(0, EXPONENTIAL) == 0.0
    assert speed_from_byte(1, EXPONENTIAL) == pytest.approx(0.1)
    assert speed_from_byte(63, EXPONENTIAL) == pytest.approx(80.0)
    for s in (1, 10, 32, 50, 63):
        assert speed_from_byte(s, EXPONENTIAL) == pytest.approx(0.1 * 800 ** ((s - 1) / 62))
        assert speed_from_byte(-s, EXPONENTIAL) == speed_from_byte(s, EXPONENTIAL)
        assert speed_from_byte(s, LINEAR) == pytest.approx(0.1 + 79.9 * (s - 1) / 62)
    assert speed_from_byte(64, EXPONENTIAL) == 150.0 == speed_from_byte(64, LINEAR)
    speeds = [speed_from_byte(s, EXPONENTIAL) for s in range(1, 64)]
    assert speeds == sorted(speeds)


def _held(config: SimConfig, motion: Motion, seconds: float) -> Dome:
    dome = Dome(config)
    dome.command(motion, 0.0)
    dome.advance_to(seconds)
    return dome


@pytest.mark.parametrize("config", [EXPONENTIAL, LINEAR], ids=["exponential", "linear"])
@pytest.mark.parametrize("byte", [1, 20, 40, 63, 64])
@pytest.mark.parametrize("seconds", [0.5, 3.0])
def test_command_held_moves_the_expected_angle(
    config: SimConfig, byte: int, seconds: float
) -> None:
    v = speed_from_byte(byte, config)
    a, latency = config.acceleration, config.latency_s
    dome = _held(config, Motion(pan=-byte), seconds)
    moving = seconds - latency
    ramp = v / a
    expected = v * moving - v * v / (2 * a) if moving >= ramp else 0.5 * a * moving**2
    assert dome.pan == pytest.approx(wrap_degrees(-expected), abs=1e-9)  # endless pan wraps
    assert dome.tilt == 0.0
    # tilt: same curve, never faster than tilt_speed_max; + is up
    if byte <= 63:
        vt = min(v, config.tilt_speed_max)
        dome = _held(config, Motion(tilt=byte), seconds)
        ramp = vt / a
        expected = vt * moving - vt * vt / (2 * a) if moving >= ramp else 0.5 * a * moving**2
        assert dome.tilt == pytest.approx(min(expected, config.tilt_max), abs=1e-9)


def test_start_stop_covers_speed_times_duration_and_latency_delays_both() -> None:
    config = SimConfig(latency_s=0.2, acceleration=100.0)
    dome = Dome(config)
    dome.command(Motion(pan=50), 1.0)
    dome.advance_to(1.2)
    assert dome.pan == 0.0  # nothing happens before the latency has passed
    dome.command(Motion(), 3.0)  # STOP
    dome.advance_to(10.0)
    # the speed-up ramp's lost distance equals the slow-down ramp's gained distance
    assert dome.pan == pytest.approx(speed_from_byte(50, config) * 2.0, abs=1e-9)
    assert not dome.moving


def test_result_does_not_depend_on_how_often_time_is_asked() -> None:
    coarse, fine = Dome(EXPONENTIAL), Dome(EXPONENTIAL)
    for dome in (coarse, fine):
        dome.command(Motion(pan=45, tilt=-30, zoom=Zoom.IN), 0.0)
        dome.command(Motion(pan=-63, tilt=10), 1.234)
    coarse.advance_to(3.0)
    for i in range(1, 3001):
        fine.advance_to(i / 1000)
    assert fine.pan == pytest.approx(coarse.pan, abs=1e-9)
    assert fine.tilt == pytest.approx(coarse.tilt, abs=1e-9)
    assert fine.zoom == pytest.approx(coarse.zoom, abs=1e-12)


def test_zoom_is_log_linear_and_takes_travel_time() -> None:
    config = SimConfig(latency_s=0.0)
    assert config.zoom_hfov_tele == pytest.approx(
        2 * math.degrees(math.atan(math.tan(math.radians(30)) / 20))
    )
    dome = Dome(config)
    assert dome.hfov == pytest.approx(60.0)
    dome.command(Motion(zoom=Zoom.IN), 0.0)
    dome.advance_to(2.0)
    assert dome.magnification == pytest.approx(math.sqrt(20.0))  # half way in log focal length
    dome.advance_to(3.999)
    assert dome.zoom < 1.0
    dome.advance_to(4.0)
    assert dome.zoom == 1.0
    assert dome.hfov == pytest.approx(config.zoom_hfov_tele)
    # zoom speed 0 is four times slower than 3
    dome.command(ZoomSpeed(0), 5.0)
    dome.command(Motion(zoom=Zoom.OUT), 5.0)
    dome.advance_to(5.0 + 8.0)
    assert dome.zoom == pytest.approx(0.5)
    dome.advance_to(5.0 + 16.0)
    assert dome.zoom == 0.0


def test_pan_endless_wraps_and_limited_pan_stops() -> None:
    dome = Dome(SimConfig(home_pan=170.0, latency_s=0.0))
    dome.command(Motion(pan=64), 0.0)
    dome.advance_to(1.0)
    assert -180.0 < dome.pan < 0.0  # 170 + ~149 wraps round
    limited = SimConfig(pan_endless=False, pan_min=-10.0, pan_max=10.0, latency_s=0.0)
    dome = Dome(limited)
    dome.command(Motion(pan=63), 0.0)
    dome.advance_to(5.0)
    assert dome.pan == 10.0
    dome.command(Motion(tilt=-63), 5.0)
    dome.advance_to(20.0)
    assert dome.tilt == -90.0


def test_presets_set_goto_clear_and_home() -> None:
    config = SimConfig(latency_s=0.0)
    dome = Dome(config)
    dome.command(Motion(pan=63, tilt=20, zoom=Zoom.IN), 0.0)
    dome.advance_to(1.0)
    dome.command(Motion(), 1.0)
    dome.advance_to(3.0)
    dome.command(Preset(PresetAction.SET, 7), 3.0)
    saved = (dome.pan, dome.tilt, dome.zoom)
    dome.home(3.0)
    dome.advance_to(10.0)
    assert (dome.pan, dome.tilt, dome.zoom) == (0.0, 0.0, 0.0)
    dome.command(Preset(PresetAction.GOTO, 7), 10.0)
    travel = max(abs(saved[0]), abs(saved[1])) / config.preset_speed
    dome.advance_to(10.0 + travel * 0.5)
    assert 0.0 < dome.pan < saved[0]
    dome.advance_to(10.0 + max(travel, saved[2] * config.zoom_travel_s) + 1e-9)
    assert dome.pan == pytest.approx(saved[0])
    assert dome.tilt == pytest.approx(saved[1])
    assert dome.zoom == pytest.approx(saved[2])
    dome.command(Preset(PresetAction.CLEAR, 7), 20.0)
    dome.command(Preset(PresetAction.GOTO, 7), 20.0)
    dome.command(Preset(PresetAction.GOTO, 9), 20.0)
    dome.advance_to(21.0)
    assert dome.counters.unknown_presets == 2


def test_position_queries_and_absolute_positions() -> None:
    dome = Dome(SimConfig(latency_s=0.0, home_pan=12.34, home_tilt=-10.0))
    assert dome.command(PositionQuery(Axis.PAN), 0.0) == _reply(Axis.PAN, 1234)
    assert dome.command(PositionQuery(Axis.TILT), 0.0) == _reply(Axis.TILT, 1000)
    assert dome.command(PositionQuery(Axis.ZOOM), 0.0) == _reply(Axis.ZOOM, round(65535 / 20))
    dome.command(AbsolutePosition(Axis.PAN, 35000), 0.0)  # 350 deg = -10: the short way
    dome.command(AbsolutePosition(Axis.TILT, 35500), 0.0)  # 5 deg above the horizon
    dome.command(AbsolutePosition(Axis.ZOOM, 65535), 0.0)
    dome.advance_to(0.05)
    assert dome.pan == pytest.approx(12.34 - 250 * 0.05)
    dome.advance_to(5.0)
    assert dome.pan == pytest.approx(-10.0)
    assert dome.tilt == pytest.approx(5.0)
    assert dome.zoom == 1.0
    assert dome.command(PositionQuery(Axis.TILT), 5.0) == _reply(Axis.TILT, 35500)


def _reply(axis: Axis, value: int) -> object:
    from ptzd.pelco.codec import PositionReply

    return PositionReply(axis=axis, value=value)


def test_proportional_speed_divides_by_magnification() -> None:
    config = SimConfig(latency_s=0.0, proportional_speed=True, acceleration=1e5)
    dome = Dome(config, zoom=1.0)
    dome.command(Motion(pan=63), 0.0)
    dome.advance_to(1.0)
    assert dome.pan == pytest.approx(80.0 / 20.0, rel=1e-3)


@pytest.mark.parametrize(
    ("section", "key"),
    [
        ({"tilt_min": 10.0, "tilt_max": 5.0}, "tilt_min"),
        ({"speed_min": 90.0}, "speed_min"),
        ({"pan_endless": False, "pan_min": 20.0, "pan_max": 10.0}, "pan_min"),
        ({"zoom_ratio": 100.0, "zoom_hfov_wide": 1.0}, "tele FOV"),
        ({"home_tilt": 50.0, "tilt_max": 40.0}, "home_tilt"),
        ({"latency_s": -1.0}, "latency_s"),
        ({"speed_curve": "cubic"}, "speed_curve"),
    ],
)
def test_impossible_config_is_a_clear_error(section: dict[str, object], key: str) -> None:
    with pytest.raises(ConfigError) as info:
        validate_config({"sim": section}, environ={})
    text = str(info.value)
    assert key in text
    assert all(problem[0].startswith("sim") for problem in info.value.problems)
