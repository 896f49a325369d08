"""The simulator's camera model: the contract formulas, rendering, projection and boxes."""

from __future__ import annotations

import math

import cv2
import numpy as np
import pytest

from ptzd.sim.camera_model import CameraModel, Pose, intrinsics, rotation

WIDE = (768, 576)
VIEW = (640, 480)


def _spec_homography(
    wide: tuple[int, int], wide_hfov: float, view: tuple[int, int], pose: Pose
) -> np.ndarray:
    """K(W,H,wide_hfov) R_pan(p) R_tilt(t) K(w,h,f)^-1 written out from interfaces.md."""

    def K(w: int, h: int, f: float) -> np.ndarray:
        F = (w / 2) / math.tan(math.radians(f) / 2)
        return np.array([[F, 0, w / 2], [0, F, h / 2], [0, 0, 1]])

    p, t = math.radians(pose.pan), math.radians(pose.tilt)
    R_pan = np.array([[math.cos(p), 0, math.sin(p)], [0, 1, 0], [-math.sin(p), 0, math.cos(p)]])
    R_tilt = np.array([[1, 0, 0], [0, math.cos(t), -math.sin(t)], [0, math.sin(t), math.cos(t)]])
    H: np.ndarray = K(*wide, wide_hfov) @ R_pan @ R_tilt @ np.linalg.inv(K(*view, pose.hfov))
    return H


def _textured(size: tuple[int, int], seed: int = 0) -> np.ndarray:
    rng = np.random.default_rng(seed)
    small = rng.integers(0, 256, (size[1] // 8, size[0] // 8, 3), dtype=np.uint8)
    return np.asarray(cv2.resize(small, size, interpolation=cv2.INTER_LINEAR), dtype=np.uint8)


@pytest.mark.parametrize(
    "pose", [Pose(0, 0, 60), Pose(12.5, -7.25, 20), Pose(-30, 15, 3.3), Pose(44, -30, 45)]
)
def test_homography_is_the_contract(pose):
    model = CameraModel(WIDE, 90.0, VIEW)
    expected = _spec_homography(WIDE, 90.0, VIEW, pose)
    np.testing.assert_allclose(model.geometry(pose).view_to_wide, expected, rtol=1e-12)
    np.testing.assert_allclose(intrinsics(640, 480, 90.0)[0, 0], 320.0)
    assert np.allclose(rotation(pose.pan, pose.tilt) @ rotation(pose.pan, pose.tilt).T, np.eye(3))


def test_points_round_trip_through_the_model():
    model = CameraModel((1920, 1080), 75.0, VIEW)
    pose = Pose(17.0, -9.0, 12.0)
    rng = np.random.default_rng(1)
    view_pts = rng.uniform([0, 0], VIEW, size=(500, 2))
    wide_pts = model.view_to_wide(view_pts, pose)
    np.testing.assert_allclose(model.wide_to_view(wide_pts, pose), view_pts, atol=1e-7)
    # and each wide point is where the contract's homography sends it
    H = _spec_homography((1920, 1080), 75.0, VIEW, pose)
    homog = np.c_[view_pts, np.ones(len(view_pts))] @ H.T
    np.testing.assert_allclose(wide_pts, homog[:, :2] / homog[:, 2:], atol=1e-7)


def test_identity_pose_reproduces_the_wide_frame():
    wide = _textured(VIEW)
    model = CameraModel(VIEW, 70.0, VIEW)
    view = model.render(wide, Pose(0.0, 0.0, 70.0))
    assert np.array_equal(view, wide)


def test_directions_pan_right_and_tilt_up():
    model = CameraModel(WIDE, 90.0, VIEW)
    centre = np.array([[WIDE[0] / 2, WIDE[1] / 2]])
    right = model.wide_to_view(centre, Pose(10.0, 0.0, 40.0))[0]
    up = model.wide_to_view(centre, Pose(0.0, 10.0, 40.0))[0]
    # looking right, the wide centre moves left in the view; looking up, it moves down
    assert right[0] < VIEW[0] / 2 and math.isclose(right[1], VIEW[1] / 2)
    assert up[1] > VIEW[1] / 2 and math.isclose(up[0], VIEW[0] / 2)


@pytest.mark.parametrize("pose", [Pose(8.0, 5.0, 30.0), Pose(-20.0, -12.0, 10.0), Pose(3, 2, 4)])
def test_rendered_marker_lands_where_projection_says(pose):
    wide = np.zeros((WIDE[1], WIDE[0], 3), np.uint8)
    model = CameraModel(WIDE, 90.0, VIEW)
    # a marker at the wide pixel that the view's (200, 150) shows, drawn as a small disc
    target = model.view_to_wide([[200.0, 150.0]], pose)[0]
    cv2.circle(
        wide,
        (round(target[0] * 16), round(target[1] * 16)),
        16 * 3,
        (255, 255, 255),
        -1,
        lineType=cv2.LINE_AA,
        shift=4,
    )
    view = model.render(wide, pose)
    expected = model.wide_to_view([target], pose)[0]
    grey = view[:, :, 0].astype(np.float64)
    ys, xs = np.nonzero(grey)
    assert len(xs) > 0
    # the disc's centroid (weighted) in the view lands on the projection
    centroid = np.array(
        [np.average(xs, weights=grey[ys, xs]), np.average(ys, weights=grey[ys, xs])]
    )
    # pixel centres are at integer coordinates in cv2's convention
    np.testing.assert_allclose(centroid, expected, atol=0.35)
    np.testing.assert_allclose(expected, [200.0, 150.0], atol=1e-9)


def test_outside_the_wide_frame_is_black_including_behind_it():
    wide = np.full((WIDE[1], WIDE[0], 3), 200, np.uint8)
    model = CameraModel(WIDE, 90.0, VIEW)
    # straight behind the wide camera: a plain homography would fold the image back in
    assert not model.render(wide, Pose(180.0, 0.0, 60.0)).any()
    # a 160-degree wide frame seen from pan 70, FOV 60: the view spans 40..100 degrees, so
    # 40..80 shows the frame, 80..90 is beside it and 90..100 is behind the wide camera
    model = CameraModel(WIDE, 160.0, VIEW)
    pose = Pose(70.0, 0.0, 60.0)
    view = model.render(wide, pose)
    u = np.arange(VIEW[0], dtype=np.float64)
    rays = model.view_to_wide(np.c_[u, np.full_like(u, 240.0)], pose)
    behind = np.isnan(rays[:, 0])
    inside = ~behind & (rays[:, 0] >= 1) & (rays[:, 0] <= WIDE[0] - 2)
    beside = ~behind & ~inside & (rays[:, 0] > WIDE[0])
    assert behind.sum() > 20 and inside.sum() > 200 and beside.sum() > 20
    assert (view[240, inside] == 200).all()
    assert not view[240, beside].any()
    assert not view[:, behind].any()


def test_box_to_view():
    model = CameraModel(WIDE, 90.0, VIEW)
    pose = Pose(5.0, -3.0, 50.0)
    box = (400.0, 300.0, 40.0, 90.0)
    got = model.box_to_view(box, pose)
    assert got is not None
    corners = [[400, 300], [440, 300], [440, 390], [400, 390]]
    projected = model.wide_to_view(corners, pose)
    x0, y0 = projected.min(axis=0)
    x1, y1 = projected.max(axis=0)
    np.testing.assert_allclose(got, (x0, y0, x1 - x0, y1 - y0), atol=1e-9)
    # far outside the view: None; straddling the edge: clipped to the view
    assert model.box_to_view((0.0, 0.0, 20.0, 20.0), pose) is None
    left_edge = model.view_to_wide([[0.0, 240.0]], pose)[0]
    clipped = model.box_to_view((left_edge[0] - 30, left_edge[1], 60.0, 20.0), pose)
    assert clipped is not None and clipped[0] == 0.0 and 0 < clipped[2] < 60
    # the view looks away from the wide frame altogether
    assert model.box_to_view(box, Pose(180.0, 0.0, 30.0)) is None


def test_box_partly_behind_the_view_is_clipped_not_folded():
    model = CameraModel((1000, 500), 170.0, VIEW)
    pose = Pose(-70.0, 0.0, 60.0)
    # a box spanning from well inside the view to far right (rays >90 deg from the view axis)
    inside = model.view_to_wide([[320.0, 240.0]], pose)[0]
    box = (inside[0], inside[1] - 5, 1000 - inside[0] - 1, 10.0)
    got = model.box_to_view(box, pose)
    assert got is not None
    assert got[0] == pytest.approx(320.0, abs=1e-6)
    assert got[0] + got[2] == pytest.approx(640.0)


def test_bad_inputs():
    model = CameraModel(WIDE, 90.0, VIEW)
    with pytest.raises(ValueError, match="768x576"):
        model.render(np.zeros((10, 10, 3), np.uint8), Pose(0, 0, 30))
    with pytest.raises(ValueError, match="FOV"):
        model.render(np.zeros((576, 768, 3), np.uint8), Pose(0, 0, 180))
    with pytest.raises(ValueError, match="view_size"):
        CameraModel(WIDE, 90.0, (0, 480))


@pytest.mark.parametrize("wide_size", [WIDE, (1920, 1080)])
def test_render_is_one_plain_warp_bit_for_bit(wide_size):
    """The fast BGRA path gives exactly what one 3-channel warpPerspective gives."""
    wide = _textured(wide_size, seed=3)
    model = CameraModel(wide_size, 90.0, VIEW)
    pose = Pose(7.3, -4.1, 17.0)
    expected = cv2.warpPerspective(
        wide,
        _spec_homography(wide_size, 90.0, VIEW, pose),
        VIEW,
        flags=cv2.INTER_LINEAR | cv2.WARP_INVERSE_MAP,
        borderMode=cv2.BORDER_CONSTANT,
        borderValue=0,
    )
    view = model.render(wide, pose)
    assert view.shape == (480, 640, 3)
    assert np.array_equal(view, expected)
    assert np.array_equal(model.render(model.prepare(wide), pose), expected)
    grey = model.render(wide[:, :, 1].copy(), pose)
    assert grey.shape == (480, 640) and np.array_equal(grey, expected[:, :, 1])
