"""Motion evidence: what moved between frames with the camera's motion removed, and the
tracker letting go of a box in which nothing moves."""

from __future__ import annotations

import cv2
import numpy as np
import pytest

from ptzd.vision.config import TrackerConfig
from ptzd.vision.stillness import MotionMap, StillCounter, motion_weights
from ptzd.vision.tracking import TrackState, make_tracker
from tests.vision_helpers import Scene, background, draw_person, twin_outcomes


def centre(box: tuple[float, float, float, float]) -> np.ndarray:
    x, y, w, h = box
    return np.array([[x + w / 2, y + h / 2, w, h]])


def shift(dx: float, dy: float) -> np.ndarray:
    return np.array([[1.0, 0.0, dx], [0.0, 1.0, dy], [0.0, 0.0, 1.0]])


def zoom_about_centre(factor: float) -> np.ndarray:
    """Zooming by `factor` about the centre of a 320 x 240 view."""
    c = 1.0 - factor
    return np.array([[factor, 0.0, 160 * c], [0.0, factor, 120 * c], [0.0, 0.0, 1.0]])


def test_a_walker_moves_and_the_background_does_not_under_a_panning_camera() -> None:
    scene = Scene(velocity=(3.0, 0.0), shift=(-4.0, 0.0))  # the camera pans 4 px/frame
    motion = MotionMap(diff_threshold=20)
    assert motion.moving_fraction(centre(scene.truth(0))) is None  # nothing before 2 frames
    motion.reset(scene.frame(0))
    for t in range(1, 4):
        motion.update(scene.frame(t), shift(*scene.shift))
    walker = motion.moving_fraction(centre(scene.truth(3)))
    background = motion.moving_fraction(np.array([[250.0, 60.0, 40.0, 80.0]]))
    assert walker is not None and background is not None
    assert walker[0] > 0.1 and background[0] < 0.005
    # without the camera's motion taken out, the textured background "moves" too
    naive = MotionMap(diff_threshold=20)
    naive.reset(scene.frame(2))
    naive.update(scene.frame(3), None)
    fraction = naive.moving_fraction(np.array([[250.0, 60.0, 40.0, 80.0]]))
    assert fraction is not None and fraction[0] > 0.03 > 6 * background[0]


def test_a_zoom_step_is_taken_out_too_and_unseen_borders_do_not_count() -> None:
    frame = Scene().frame(0)
    zoom = np.array([[1.2, 0.0, -0.2 * 160], [0.0, 1.2, -0.2 * 120], [0.0, 0.0, 1.0]])
    zoomed = np.asarray(cv2.warpPerspective(frame, zoom, (320, 240)), np.uint8)
    motion = MotionMap(diff_threshold=20)
    motion.reset(frame)
    motion.transform(zoom)
    motion.update(zoomed, None)
    whole = motion.moving_fraction(np.array([[160.0, 120.0, 320.0, 240.0]]))
    assert whole is not None and whole[0] < 0.01
    # a pan to the right: the strip the previous frame never saw is unknown, not motion
    panned = np.asarray(cv2.warpPerspective(frame, shift(-30, 0), (320, 240)), np.uint8)
    motion.reset(frame)
    motion.update(panned, shift(-30, 0))
    strip = motion.moving_fraction(np.array([[305.0, 120.0, 30.0, 240.0]]))
    assert strip is not None and strip[0] == 0.0


def test_a_zoom_step_s_resampled_edges_are_not_motion_but_a_walker_is() -> None:
    # zooming in on a view that was itself zoomed out: the previous frame warped to match is
    # an enlarged, twice-resampled image, and every sharp edge in it comes out blurred
    yy, xx = np.mgrid[0:240, 0:320]
    board = np.dstack([((xx // 8 + yy // 8) % 2 * 200 + 20).astype(np.uint8)] * 3)

    def view(image: np.ndarray, factor: float) -> np.ndarray:
        return np.asarray(cv2.warpPerspective(image, zoom_about_centre(factor), (320, 240)))

    motion = MotionMap(diff_threshold=20)
    motion.reset(view(board, 1 / 1.1))
    motion.transform(zoom_about_centre(1.1))
    motion.update(view(board, 1.0), None)
    moving = motion.moving()
    # (a third of the board's pixels, the thin lines along its edges, without the opening)
    assert moving is not None and moving.mean() < 0.001
    # a walker's motion is a blob, not a line: it survives
    scene = Scene(velocity=(3.0, 0.0))
    step = zoom_about_centre(1.1)
    motion.reset(scene.frame(7))
    motion.transform(step)
    motion.update(view(scene.frame(8), 1.1), None)
    x, y, w, h = scene.truth(8)
    cx, cy, _ = step @ np.array([x + w / 2, y + h / 2, 1.0])
    walker = motion.moving_fraction(np.array([[cx, cy, 1.1 * w, 1.1 * h]]))
    assert walker is not None and walker[0] > 0.15


def test_boxes_are_scored_at_once_and_clipped_to_the_frame() -> None:
    still = np.full((100, 100), 50, np.uint8)
    moved = still.copy()
    moved[:, 50:] = 200  # the right half changed
    motion = MotionMap(diff_threshold=20)
    motion.reset(still)
    motion.update(moved, None)
    boxes = np.array([[25.0, 50.0, 50.0, 100.0], [75.0, 50.0, 50.0, 100.0], [95.0, 50, 30, 20]])
    fractions = motion.moving_fraction(boxes)
    assert fractions is not None
    assert fractions.tolist() == [0.0, 1.0, 1.0]  # the last box is clipped at x = 100


def test_the_tracker_lets_go_of_a_box_in_which_nothing_moves() -> None:
    standing = Scene(velocity=(0.0, 0.0))
    walking = Scene(velocity=(2.0, 0.5))
    results = {}
    for name, scene, still_frames in [
        ("standing", standing, 10),
        ("walking", walking, 10),
        ("standing, test off", standing, 0),
    ]:
        tracker = make_tracker(
            TrackerConfig(kind="color", stillness={"still_frames": still_frames})
        )
        tracker.init(scene.frame(0), scene.truth(0))
        results[name] = [tracker.update(scene.frame(t)).state for t in range(1, 40)]
    # nothing moved in the standing target's box for 10 frames: occluded, then lost
    assert results["standing"][:9] == [TrackState.TRACKING] * 9
    assert TrackState.TRACKING not in results["standing"][10:]
    assert results["standing"][-1] is TrackState.LOST
    assert set(results["walking"]) == {TrackState.TRACKING}
    assert set(results["standing, test off"]) == {TrackState.TRACKING}


@pytest.mark.parametrize(
    "config",
    [
        TrackerConfig(kind="color", stillness={"still_frames": 25}),
        TrackerConfig(kind="rf", rf={"still_frames": 25}),
        TrackerConfig(kind="svm", svm={"still_frames": 25}),
    ],
    ids=["color", "rf", "svm"],
)
def test_a_still_box_is_let_go_while_the_zoom_hunts(config: TrackerConfig) -> None:
    # a still object with the zoom stepping in and out on it every few seconds: each step
    # rescales the image, and that is not motion
    scene = Scene(velocity=(0.0, 0.0))
    tracker = make_tracker(config)
    tracker.init(scene.frame(0), scene.truth(0))
    factor, states = 1.0, []
    for t in range(1, 60):
        if t % 8 == 0:  # a zoom step: in, out, in, ...
            step = 1.1 if (t // 8) % 2 else 1 / 1.1
            factor *= step
            tracker.rescale(step, (160.0, 120.0))
        zoom = zoom_about_centre(factor)
        view = np.asarray(cv2.warpPerspective(scene.frame(t), zoom, (320, 240)), np.uint8)
        states.append(tracker.update(view).state)
    assert states[:20] == [TrackState.TRACKING] * 20
    assert TrackState.LOST in states[25:]


def test_a_still_box_in_doubt_is_let_go_sooner() -> None:
    # a figure standing still; from frame 5 most of its trousers are another colour, so the
    # box scores in doubt (under learn_threshold) and its model stops learning: a patch of
    # background that half matches the target looks like this to the tracker
    box = (140.0, 90.0, 24.0, 60.0)

    def frame(t: int, changed: float) -> np.ndarray:
        img = background(320, 240, 0).copy()
        draw_person(img, box, (40, 40, 200), (160, 60, 20))
        if t >= 5:
            cv2.rectangle(img, (140, 120), (140 + round(24 * changed) - 1, 149), (60, 120, 40), -1)
        return img

    def first_occluded(changed: float, doubt_frames: int) -> tuple[int, float]:
        stillness = {"doubt_frames": doubt_frames}
        tracker = make_tracker(TrackerConfig(kind="color", stillness=stillness))
        tracker.init(frame(0, changed), box)
        results = [tracker.update(frame(t, changed)) for t in range(1, 80)]
        states = [r.state for r in results]
        confidence = float(np.median([r.confidence for r in results[10:20]]))
        return 1 + states.index(TrackState.OCCLUDED), confidence

    # in doubt: let go 20 still frames after the change instead of 50
    at, confidence = first_occluded(0.9, 20)
    assert 0.6 < confidence < 0.75
    assert 20 <= at <= 30
    assert first_occluded(0.9, 0)[0] >= 40
    # a box that still matches well (the model learns the change) is held the full 50
    at, confidence = first_occluded(0.8, 20)
    assert confidence > 0.75 and at >= 40


def test_motion_weights_favour_the_boxes_in_which_something_moved() -> None:
    moved = np.array([0.0, 0.04, 0.16])
    weights = motion_weights(moved, floor=0.2, min_fraction=0.02)
    assert weights is not None
    # floor for nothing, 1 for the most, the square root of the share between
    assert weights.tolist() == pytest.approx([0.2, 0.2 + 0.8 * 0.5, 1.0])
    # no evidence: unknown, nothing moved anywhere, or weighting off
    assert motion_weights(None, 0.2, 0.02) is None
    assert motion_weights(np.array([0.0, 0.01]), 0.2, 0.02) is None
    assert motion_weights(moved, 1.0, 0.02) is None


def test_the_still_counter_counts_still_frames_in_a_row() -> None:
    counter = StillCounter(frames=3, min_fraction=0.02)
    assert [counter.count(m) for m in (0.0, 0.01, None, 0.0)] == [False, False, False, True]
    assert counter.count(0.5) is False and counter.run == 0  # something moved: start over
    off = StillCounter(frames=0, min_fraction=0.02)
    assert not any(off.count(0.0) for _ in range(20))


def test_rf_follows_the_walker_not_his_still_twin() -> None:
    # (the twin wears his colours: the colour vote is off in the forests-only variants)
    variants = {
        "motion": {},
        "appearance only": {"motion_floor": 1.0, "still_frames": 0, "colour_weight": 0.0},
        "still test only": {"motion_floor": 1.0, "colour_weight": 0.0},
    }
    outcome = twin_outcomes(2.5, 60, "rf", variants, seeds=5)
    # with the motion weights every seed follows him
    assert all(s is TrackState.TRACKING and w > 0.5 for s, w, _ in outcome["motion"])
    # on appearance alone the twin is as good: some seeds stay on it, tracking it
    stayed = [i for i, (s, _, t) in enumerate(outcome["appearance only"]) if t > 0.3]
    assert stayed and all(outcome["appearance only"][i][0] is TrackState.TRACKING for i in stayed)
    # the still test alone lets go of the twin those seeds were left on
    assert all(outcome["still test only"][i][0] is not TrackState.TRACKING for i in stayed)
