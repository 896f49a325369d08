"""A loose first box fitted to the moving person in it, answered in the drawn framing."""

from __future__ import annotations

import cv2
import numpy as np
import pytest

from ptzd.vision.auto import running_kind
from ptzd.vision.config import FirstBoxConfig, TrackerConfig
from ptzd.vision.first_box import FittedTracker, Framing, fit_to_motion
from ptzd.vision.particle_filter import zoom_homography
from ptzd.vision.tracking import Box, TrackState, make_bare_tracker, make_tracker
from tests.vision_helpers import Frame, Scene, iou

CONFIG = FirstBoxConfig()


def loose(box: Box, scale: float) -> Box:
    x, y, w, h = box
    return (x + w / 2 - scale * w / 2, y + h / 2 - scale * h / 2, scale * w, scale * h)


def fitted_tracker(kind: str = "color") -> FittedTracker:
    tracker = make_tracker(TrackerConfig(kind=kind, seed=0))
    assert isinstance(tracker, FittedTracker)
    return tracker


def walker_mask(shape: tuple[int, int], x0: int, y0: int, x1: int, y1: int) -> np.ndarray:
    """Moving pixels as a walker leaves them: his outline and a stripe down his middle (a
    swinging arm), nothing inside the plain cloth."""
    moving = np.zeros(shape, np.uint8)
    moving[y0:y1, x0 : x0 + 2] = 1
    moving[y0:y1, x1 - 2 : x1] = 1
    moving[y0 : y0 + 2, x0:x1] = 1
    moving[y1 - 2 : y1, x0:x1] = 1
    moving[y0:y1, (x0 + x1) // 2] = 1
    return moving


def test_the_still_margin_is_trimmed_to_the_moving_person() -> None:
    moving = walker_mask((200, 200), 80, 40, 110, 140)
    assert fit_to_motion(moving, (70.0, 25.0, 50.0, 130.0), CONFIG) == (80.0, 40.0, 30.0, 100.0)


def test_a_tight_box_comes_back_as_it_was_drawn() -> None:
    moving = walker_mask((200, 200), 80, 40, 110, 140)
    drawn = (79.6, 40.3, 30.2, 99.5)  # rounds onto the outline: no strip is still
    assert fit_to_motion(moving, drawn, CONFIG) == drawn


def test_untrimmed_sides_keep_their_drawn_edges_even_outside_the_frame() -> None:
    moving = walker_mask((200, 200), 0, 40, 30, 140)
    x, y, w, h = fit_to_motion(moving, (-10.0, 40.0, 45.0, 100.0), CONFIG)
    # the left side runs off the frame and was not trimmed: it stays where it was drawn
    assert (x, y, x + w, y + h) == (-10.0, 40.0, 30.0, 140.0)


def test_no_more_than_max_trim_comes_off_a_side() -> None:
    moving = np.zeros((300, 300), np.uint8)
    moving[90:170, 130:170] = 1
    x, y, w, h = fit_to_motion(moving, (100.0, 30.0, 100.0, 200.0), CONFIG)
    assert (x, y, w, h) == (125.0, 80.0, 50.0, 100.0)  # a quarter from each side


def test_motion_too_thin_to_be_a_person_keeps_the_box() -> None:
    # one edge of a plain figure moved (its trailing edge lies on something of its colour,
    # or outside a box that lags it): what the fit would keep is mostly still
    moving = np.zeros((200, 200), np.uint8)
    moving[40:140, 108:110] = 1
    drawn = (70.0, 25.0, 50.0, 130.0)
    assert fit_to_motion(moving, drawn, CONFIG) == drawn
    loose_config = CONFIG.model_copy(update={"min_person_share": 0.0})
    assert fit_to_motion(moving, drawn, loose_config) != drawn


@pytest.mark.parametrize(
    "moving",
    [
        np.zeros((200, 200), np.uint8),  # a person standing still
        walker_mask((200, 200), 95, 95, 99, 99),  # a few pixels: under min_moving_fraction
    ],
)
def test_a_box_in_which_hardly_anything_moved_is_kept(moving: np.ndarray) -> None:
    drawn = (70.0, 25.0, 50.0, 130.0)
    assert fit_to_motion(moving, drawn, CONFIG) == drawn


def test_a_box_too_small_in_the_frame_is_kept() -> None:
    moving = np.ones((100, 100), np.uint8)
    drawn = (95.0, 10.0, 20.0, 40.0)  # 5 px of it inside the frame
    assert fit_to_motion(moving, drawn, CONFIG) == drawn


def test_the_framing_round_trips_and_keeps_its_proportions() -> None:
    fitted, drawn = (100.0, 50.0, 20.0, 60.0), (92.0, 41.0, 30.0, 80.0)
    framing = Framing.between(fitted, drawn)
    assert framing.drawn(fitted) == pytest.approx(drawn)
    # the fitted box moved 10 px right and doubled: the drawn centre was 3 px left of the
    # fitted one and 1 px below, and is 6 px left and 2 px below after
    assert framing.drawn((100.0, 20.0, 40.0, 120.0)) == pytest.approx((84.0, 2.0, 60.0, 160.0))


class TexturedScene(Scene):
    """`Scene` with a checked cloth on the walker, as real clothes and limbs have: moving,
    it changes pixels all over him, not only at his outline."""

    def frame(self, t: int) -> Frame:
        img = super().frame(t)
        x, y, w, h = (round(v) for v in self.truth(t))
        rows, cols = np.mgrid[0:h, 0:w]
        checks = ((rows // 4 + cols // 4) % 2).astype(np.int16) * 60 - 30
        patch = img[y : y + h, x : x + w].astype(np.int16) + checks[..., None]
        img[y : y + h, x : x + w] = np.clip(patch, 0, 255).astype(np.uint8)
        return img


def run(
    tracker: FittedTracker, scene: Scene, drawn: Box, frames: int, ego: np.ndarray | None = None
) -> list[tuple[Box, TrackState]]:
    tracker.init(scene.frame(0), drawn)
    out = []
    for t in range(1, frames):
        result = tracker.update(scene.frame(t), ego)
        out.append((result.box, result.state))
    return out


def fitted_now(tracker: FittedTracker, answered: Box) -> Box:
    """The box the inner tracker follows, from the box answered in the drawn framing."""
    f = tracker.framing
    x, y, w, h = answered
    fw, fh = w / f.kw, h / f.kh
    cx, cy = x + w / 2 - f.dx * fw, y + h / 2 - f.dy * fh
    return (cx - fw / 2, cy - fh / 2, fw, fh)


@pytest.mark.parametrize(
    ("kind", "cloth"),
    [("color", TexturedScene), ("rf", TexturedScene), ("svm", TexturedScene),
     ("auto", TexturedScene), ("color", Scene)],
)  # fmt: skip
def test_a_loose_first_box_is_refitted_to_the_walker_and_answered_in_its_framing(
    kind: str, cloth: type[Scene]
) -> None:
    scene = cloth(start=(60.0, 80.0, 24.0, 60.0), velocity=(2.0, 0.5))
    tracker = fitted_tracker(kind)
    drawn = loose(scene.truth(0), 1.5)
    answers = run(tracker, scene, drawn, 20)
    assert running_kind(tracker, kind) == ("color" if kind == "auto" else kind)
    # the walker plus the strip he swept in the two frames (2 px a frame), not the margin
    framing = tracker.framing
    assert framing.kh == pytest.approx(1.5, abs=0.1)
    assert 1.5 * 24 / (24 + 2 * 2 + 2) <= framing.kw <= 1.5 + 0.05
    box, state = answers[-1]
    assert state is TrackState.TRACKING
    # what comes out has the drawn box's margins round where the walker now is ...
    assert iou(box, loose(scene.truth(19), 1.5)) > 0.6
    # ... and the tracker inside follows the walker himself
    assert iou(fitted_now(tracker, box), scene.truth(19)) > 0.6


class GravelScene(TexturedScene):
    """`TexturedScene` on fine gravel that moves with the ground as the camera pans."""

    def frame(self, t: int) -> Frame:
        img = super().frame(t)
        rows, cols = np.mgrid[0 : self.height, 0 : self.width]
        pan = round(self.shift[0] * t)
        gravel = (((cols - pan) // 3 + rows // 3) % 2).astype(np.int16) * 80 - 40
        x, y, w, h = (round(v) for v in self.truth(t))
        gravel[y : y + h, x : x + w] = 0
        out: Frame = np.clip(img.astype(np.int16) + gravel[..., None], 0, 255).astype(np.uint8)
        return out


@pytest.mark.parametrize("told", [True, False])
def test_the_camera_s_own_motion_is_taken_out_of_the_fit(told: bool) -> None:
    # a pan of 3 px a frame over gravel; the walker steps 2 px a frame the same way
    scene = GravelScene(start=(100.0, 80.0, 24.0, 60.0), velocity=(2.0, 0.0), shift=(3.0, 0.0))
    tracker = fitted_tracker()
    answers = run(
        tracker, scene, loose(scene.truth(0), 1.5), 3, ego=np.array(scene.shift) if told else None
    )
    if not told:  # the gravel moved everywhere: nothing to trim
        assert tracker.framing == Framing()
        return
    assert tracker.framing.kh == pytest.approx(1.5, abs=0.1)
    # the gathered motion is his, in this frame's pixels: from where he stood two frames
    # ago (4 px back, the pan taken out) to where he is
    x, _, w, _ = fitted_now(tracker, answers[-1][0])
    truth = scene.truth(3 - 1)
    assert (x, w) == pytest.approx((truth[0] - 4, truth[2] + 4), abs=1.0)


@pytest.mark.parametrize("cloth", [TexturedScene, Scene])
def test_a_tight_first_box_is_left_to_the_tracker_as_drawn(cloth: type[Scene]) -> None:
    # in plain cloth (`Scene`) only his outline moves, and the edge he leaves behind is
    # outside the box that follows him: what lies between his edges is him all the same
    scene = cloth(start=(60.0, 80.0, 24.0, 60.0), velocity=(2.0, 0.5))
    fitted = fitted_tracker()
    bare = make_bare_tracker(TrackerConfig(kind="color", seed=0))
    answers = run(fitted, scene, scene.truth(0), 12)
    assert fitted.framing == Framing()
    bare.init(scene.frame(0), scene.truth(0))
    for t, (box, state) in enumerate(answers, start=1):
        result = bare.update(scene.frame(t))
        assert (result.box, result.state) == (box, state)  # the same tracker, run for run


def test_a_box_with_still_strips_at_a_side_only_is_not_refitted() -> None:
    # drawn tight in height but with 12 px of ground to his right: still strips at a side
    # are what a tight box has by a still arm or a planted leg, not a drawn margin
    scene = TexturedScene(start=(60.0, 80.0, 24.0, 60.0), velocity=(2.0, 0.5))
    x, y, w, h = scene.truth(0)
    tracker = fitted_tracker()
    run(tracker, scene, (x, y, w + 12.0, h), 4)
    assert tracker.framing == Framing()


def test_a_walker_standing_still_keeps_the_drawn_box() -> None:
    scene = TexturedScene(start=(60.0, 80.0, 24.0, 60.0), velocity=(0.0, 0.0))
    tracker = fitted_tracker()
    run(tracker, scene, loose(scene.truth(0), 1.5), 5)
    assert tracker.framing == Framing()


def test_a_new_init_starts_from_the_drawn_framing_again() -> None:
    scene = TexturedScene(start=(60.0, 80.0, 24.0, 60.0), velocity=(2.0, 0.5))
    tracker = fitted_tracker()
    run(tracker, scene, loose(scene.truth(0), 1.5), 4)
    assert tracker.framing != Framing()
    tracker.init(scene.frame(4), scene.truth(4))
    assert tracker.framing == Framing()


def test_the_fit_can_be_turned_off() -> None:
    config = TrackerConfig.model_validate({"kind": "color", "first_box": {"enabled": False}})
    assert not isinstance(make_tracker(config), FittedTracker)


def test_a_zoom_while_the_motion_is_gathered_is_taken_out_too() -> None:
    scene = GravelScene(start=(100.0, 80.0, 24.0, 60.0), velocity=(2.0, 0.0))
    tracker = fitted_tracker()
    factor, centre = 1.2, (160.0, 120.0)
    zoom = zoom_homography(factor, centre)
    tracker.init(scene.frame(0), loose(scene.truth(0), 1.5))
    tracker.update(scene.frame(1))
    tracker.rescale(factor, centre)  # between frames 1 and 2, as the daemon hands it in
    zoomed: Frame = np.asarray(
        cv2.warpPerspective(scene.frame(2), zoom, (scene.width, scene.height)), np.uint8
    )
    answer = tracker.update(zoomed)
    assert tracker.framing.kh == pytest.approx(1.5, abs=0.1)
    x, _, w, _ = fitted_now(tracker, answer.box)
    tx, _, tw, _ = scene.truth(2)
    # from where he stood two frames ago to where he is, both seen through the zoom
    assert (x, w) == pytest.approx(
        (centre[0] + factor * (tx - 4 - centre[0]), factor * (tw + 4)), abs=1.5
    )
