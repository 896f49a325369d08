"""Commanded camera motion as image motion, against the simulator's camera model."""

from __future__ import annotations

import math

import numpy as np
import pytest

from ptzd.control.config import DomeModelConfig
from ptzd.control.egomotion import (
    DomeEstimate,
    Pose,
    apply_homography,
    byte_for_rate,
    focal_ratio,
    hfov_after_factor,
    rate_for_byte,
    view_homography,
)
from ptzd.sim.camera_model import CameraModel

VIEW = (640, 480)


def test_homography_moves_scene_points_like_the_camera_model() -> None:
    model = CameraModel((768, 576), 90.0, VIEW)
    before, after = Pose(3.0, -2.0, 40.0), Pose(5.5, -1.0, 31.0)
    wide_points = np.array([[300.0, 250.0], [420.0, 330.0], [380.0, 290.0]])
    in_before = model.wide_to_view(wide_points, before)
    in_after = model.wide_to_view(wide_points, after)
    h = view_homography(VIEW, before, after)
    for (xa, ya), (xb, yb) in zip(in_before, in_after, strict=True):
        u, v = apply_homography(h, xa, ya)
        assert u == pytest.approx(xb, abs=1e-6) and v == pytest.approx(yb, abs=1e-6)


def test_pan_right_shifts_the_image_left_and_tilt_up_shifts_it_down() -> None:
    focal = (VIEW[0] / 2) / math.tan(math.radians(30.0))  # hfov 60
    pan = view_homography(VIEW, Pose(0, 0, 60), Pose(1.0, 0, 60))
    u, v = apply_homography(pan, 320, 240)
    assert u == pytest.approx(320 - focal * math.tan(math.radians(1.0)))
    assert v == pytest.approx(240)
    tilt = view_homography(VIEW, Pose(0, 0, 60), Pose(0, 1.0, 60))
    u, v = apply_homography(tilt, 320, 240)
    assert u == pytest.approx(320) and v > 240


def test_zoom_is_a_scaling_about_the_centre() -> None:
    h = view_homography(VIEW, Pose(0, 0, 60), Pose(0, 0, 30))
    factor = focal_ratio(60, 30)
    u, v = apply_homography(h, 420, 300)
    assert u == pytest.approx(320 + 100 * factor) and v == pytest.approx(240 + 60 * factor)
    assert hfov_after_factor(60, factor) == pytest.approx(30)


def test_speed_curve_inverts() -> None:
    model = DomeModelConfig()
    assert rate_for_byte(63, model) == pytest.approx(80.0)
    assert rate_for_byte(1, model) == pytest.approx(0.1)
    assert rate_for_byte(-63, model, tilt=True) == pytest.approx(-40.0)
    for byte in (1, 5, 20, 40, 63, -7, -33):
        assert byte_for_rate(rate_for_byte(byte, model), model) == byte
    assert byte_for_rate(0.0, model) == 0
    assert byte_for_rate(1e-6, model) == 1  # any motion at all is at least speed 1
    linear = DomeModelConfig(speed_curve="linear", speed_min=1.0, speed_max=63.0)
    assert rate_for_byte(32, linear) == pytest.approx(32.0)


def test_dome_estimate_dead_reckons_commands() -> None:
    model = DomeModelConfig()
    estimate = DomeEstimate(model, zoom_log_rate=0.75, start=Pose(0.0, 0.0, 60.0))
    estimate.command(63, -63, 1)
    pose = estimate.advance(0.5)
    assert pose.pan == pytest.approx(40.0)
    assert pose.tilt == pytest.approx(-20.0)
    assert focal_ratio(60.0, pose.hfov) == pytest.approx(math.exp(0.375))
    estimate.command(0, 0, 0)
    assert estimate.advance(1.0) == pose


def test_a_command_between_ticks_ends_the_motion_it_replaces_at_its_own_time() -> None:
    """A manual command arrives between control ticks: the pan in force until then counts,
    and the new motion starts at the command's time, not at the last tick's."""
    estimate = DomeEstimate(DomeModelConfig(), zoom_log_rate=0.75, start=Pose(0.0, 0.0, 60.0))
    estimate.command(63, 0, 0, time=0.0)  # 80 deg/s
    estimate.command(0, 0, 0, time=0.5)  # no advance in between
    assert estimate.advance_to(1.0).pan == pytest.approx(40.0)
    assert estimate.pose_at(0.25).pan == pytest.approx(20.0)


def test_dome_estimate_stops_where_the_dome_does() -> None:
    """A zoom held past the lens's end, or a tilt past its limit, moves the estimate no
    further than the dome: the tracker must not be told of a zoom that is not happening."""
    model = DomeModelConfig(hfov_wide=60.0, hfov_tele=3.0, tilt_min=-90.0, tilt_max=10.0)
    estimate = DomeEstimate(model, zoom_log_rate=0.75, start=Pose(0.0, 0.0, 50.0))
    estimate.command(0, 63, -1)  # zoom out and tilt up, for a long time
    for _ in range(100):
        pose = estimate.advance(0.1)
    assert pose.hfov == pytest.approx(60.0) and pose.tilt == pytest.approx(10.0)
    before = estimate.pose
    assert estimate.advance(0.1) == before  # at both ends: not moving at all
    estimate.command(0, -63, 1)
    for _ in range(200):
        pose = estimate.advance(0.1)
    assert pose.hfov == pytest.approx(3.0) and pose.tilt == pytest.approx(-90.0)
    with pytest.raises(ValueError, match="tilt_min"):
        DomeModelConfig(tilt_min=20.0, tilt_max=10.0)


def test_dome_estimate_recalls_the_pose_at_a_past_time() -> None:
    """A frame taken before the latest commands is tracked in the pose of its own time:
    the estimate replays the commands in force then, not the ones sent since."""
    model = DomeModelConfig()
    estimate = DomeEstimate(model, zoom_log_rate=0.75, start=Pose(0.0, 0.0, 60.0), time=0.0)
    truth: dict[float, Pose] = {}
    for step, (pan, tilt, zoom) in enumerate([(63, 0, 0), (-40, 20, 1), (0, 0, -1), (0, 0, 0)]):
        for k in range(5):
            t = round(step * 0.5 + k * 0.1, 6)
            truth[t] = estimate.advance_to(t)
        estimate.advance_to(round(step * 0.5 + 0.5, 6))
        estimate.command(pan, tilt, zoom)
    for t, pose in truth.items():
        recalled = estimate.pose_at(t)
        assert (recalled.pan, recalled.tilt, recalled.hfov) == pytest.approx(
            (pose.pan, pose.tilt, pose.hfov)
        ), t
    assert estimate.pose_at(-5.0) == Pose(0.0, 0.0, 60.0)  # before it all: the start
    later = estimate.pose_at(10.0)  # a later time advances the estimate itself
    assert estimate.time == 10.0 and estimate.pose == later


def test_zoom_then_rotation_at_the_new_fov_is_the_full_homography() -> None:
    # The daemon gives the tracker the zoom as rescale(factor, centre) and then the rotation
    # taken at the new FOV as ego-motion; together they must equal K_b R_b^T R_a K_a^-1.
    before, after = Pose(2.0, 1.0, 40.0), Pose(4.0, -1.5, 28.0)
    factor = focal_ratio(before.hfov, after.hfov)
    cx, cy = VIEW[0] / 2, VIEW[1] / 2
    zoom = np.array([[factor, 0, cx * (1 - factor)], [0, factor, cy * (1 - factor)], [0, 0, 1]])
    rotation = view_homography(VIEW, Pose(before.pan, before.tilt, after.hfov), after)
    composed = rotation @ zoom
    full = view_homography(VIEW, before, after)
    assert np.allclose(composed / composed[2, 2], full, atol=1e-9)
