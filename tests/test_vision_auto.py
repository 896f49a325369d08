"""`kind = "auto"`: the day tracker on colour frames, the night tracker on grey ones."""

from __future__ import annotations

import io
import json
from pathlib import Path

import cv2
import numpy as np
import pytest
from pydantic import ValidationError

from ptzd.logs import configure_logging
from ptzd.vision.auto import AutoTracker, colour_share
from ptzd.vision.config import TrackerConfig
from ptzd.vision.features import to_bgr, to_grey
from ptzd.vision.tracking import TrackState, make_bare_tracker, make_tracker
from tests.vision_helpers import Frame, Scene, iou


def _auto(**auto: object) -> AutoTracker:
    tracker = make_bare_tracker(TrackerConfig.model_validate({"kind": "auto", "auto": auto}))
    assert isinstance(tracker, AutoTracker)
    return tracker


def _grey(frame: Frame) -> Frame:
    """As a day/night camera's decoder gives a night frame: three equal channels."""
    return to_bgr(to_grey(frame))


def _tinted(frame: Frame, rows: int) -> Frame:
    """`frame` in grey with its first `rows` rows tinted red by 20 levels."""
    tinted = _grey(frame).copy()
    tinted[:rows, :, 2] = np.minimum(tinted[:rows, :, 2], 235) + 20
    return tinted


def test_colour_share_by_hand() -> None:
    frame = np.zeros((2, 2, 3), np.uint8)
    frame[0, 0] = (10, 20, 30)  # spread 20: coloured
    frame[0, 1] = (100, 104, 107)  # 7: not
    frame[1, 0] = (70, 70, 70)  # 0: not
    frame[1, 1] = (50, 40, 48)  # 10: coloured
    assert colour_share(frame, step=1) == 0.5
    assert colour_share(frame, step=2) == 1.0  # only (0, 0) is looked at
    frame[1, 0] = (0, 15, 3)  # dark (brightest channel < 16): left out
    assert colour_share(frame, step=1) == pytest.approx(2 / 3)
    assert colour_share(np.full((4, 4, 3), (15, 0, 9), np.uint8)) == 0.0  # nothing lit
    assert colour_share(frame[..., 0]) == 0.0
    assert colour_share(frame[..., :1]) == 0.0
    assert colour_share(_grey(Scene().frame(0))) == 0.0
    assert colour_share(Scene().frame(0)) > 0.5
    # a view half off the wide video (the simulator renders black there) reads as the half
    # that shows something
    half = Scene().frame(0).copy()
    half[:, :160] = 0
    assert colour_share(half) == pytest.approx(colour_share(Scene().frame(0)[:, 160:]))
    with pytest.raises(ValueError, match="HxWx3"):
        colour_share(np.zeros((4, 4, 2), np.uint8))


@pytest.mark.parametrize("fourcc", ["MJPG", "mp4v"])
def test_decoded_grey_video_has_no_colour(fourcc: str, tmp_path: Path) -> None:
    """A decoder's YUV -> BGR rounding spreads a grey frame's channels by 2-3 levels: still
    no coloured pixel, where a colour frame of the same scene is mostly coloured. (Grey
    first: an inter-frame codec's first grey frames after colour ones carry a little of
    their chroma, 1.7 % coloured pixels with MPEG-4 alternating the two, still under the
    default `mono_below`.)"""
    scene = Scene()
    path = tmp_path / "grey.avi"
    writer = cv2.VideoWriter(str(path), cv2.VideoWriter.fourcc(*fourcc), 10.0, (320, 240))
    assert writer.isOpened()
    for t in range(3):
        writer.write(_grey(scene.frame(t)))
    for t in range(3):
        writer.write(scene.frame(t))
    writer.release()
    capture = cv2.VideoCapture(str(path))
    shares = []
    while True:
        ok, frame = capture.read()
        if not ok:
            break
        shares.append(colour_share(np.asarray(frame, np.uint8)))
    capture.release()
    assert len(shares) == 6
    assert shares[:3] == [0.0, 0.0, 0.0]
    assert min(shares[3:]) > 0.5


def test_picks_the_tracker_by_the_frames() -> None:
    scene = Scene()
    day = _auto()
    day.init(scene.frame(0), scene.truth(0))
    assert day.kind == "color"
    night = _auto()
    night.init(_grey(scene.frame(0)), scene.truth(0))
    assert night.kind == "rf"
    single = _auto(night="svm")
    single.init(to_grey(scene.frame(0)), scene.truth(0))
    assert single.kind == "svm"
    with pytest.raises(RuntimeError, match="init"):
        _auto().update(scene.frame(0))


def test_dead_band_keeps_the_last_mode() -> None:
    scene = Scene(velocity=(1.0, 0.0))
    tracker = _auto(mono_below=0.02, colour_above=0.15)
    # 240 rows, every 8th looked at: 8 tinted rows are 1 of 30 grid rows coloured
    share = {rows: colour_share(_tinted(scene.frame(0), rows)) for rows in (0, 8, 24, 64)}
    assert share == pytest.approx({0: 0.0, 8: 1 / 30, 24: 3 / 30, 64: 8 / 30})
    # in the band with nothing to go on: the nearer side (0.1 > the middle 0.085: colour)
    tracker.init(_tinted(scene.frame(0), 24), scene.truth(0))
    assert tracker.kind == "color"
    kinds = []
    for t, rows in enumerate([24, 0, 24, 24, 64, 8, 24, 0], start=1):
        tracker.update(_tinted(scene.frame(t), rows))
        kinds.append(tracker.kind)
    night, day = "rf", "color"
    assert kinds == [day, night, night, night, day, day, day, night]
    fresh = _auto(mono_below=0.02, colour_above=0.15)
    fresh.init(_tinted(scene.frame(0), 8), scene.truth(0))  # 0.033: nearer mono
    assert fresh.kind == "rf"


def test_band_must_be_ordered() -> None:
    with pytest.raises(ValidationError, match="colour_above must be >= mono_below"):
        TrackerConfig.model_validate(
            {"kind": "auto", "auto": {"mono_below": 0.5, "colour_above": 0.4}}
        )
    with pytest.raises(ValueError, match="kind = 'auto'"):
        AutoTracker(TrackerConfig(kind="color"))


@pytest.mark.parametrize("shift", [(0.0, 0.0), (-4.0, 1.0)])
def test_dusk_mid_track_hands_over_on_the_target(
    shift: tuple[float, float],
) -> None:
    """The camera goes to night mode while it pans after a walker: rf takes over on him."""
    scene = Scene(velocity=(3.0, 0.5), shift=shift)
    ego = np.array(shift) if shift != (0.0, 0.0) else None
    tracker = _auto()
    tracker.init(scene.frame(0), scene.truth(0))
    for t in range(1, 20):
        tracker.update(scene.frame(t), ego)
    by_day = tracker.kind
    log = io.StringIO()
    configure_logging(level="info", fmt="json", stream=log)  # whatever tests before set
    first = tracker.update(_grey(scene.frame(20)), ego)
    assert (by_day, tracker.kind) == ("color", "rf")
    events = [json.loads(line) for line in log.getvalue().splitlines()]
    switched = [e for e in events if e["event"] == "tracker_switched"]
    assert len(switched) == 1
    assert (switched[0]["previous"], switched[0]["kind"], switched[0]["reason"]) == (
        "color",
        "rf",
        "frames",
    )
    # rf starts on the colour tracker's last box carried into the grey frame by the
    # camera's motion and the walker's (left out, either is 3-4 px off: IoU 0.7-0.8)
    assert iou(tuple(switched[0]["bbox"]), scene.truth(20)) > 0.85
    assert iou(first.box, scene.truth(20)) > 0.6
    for t in range(21, 60):
        result = tracker.update(_grey(scene.frame(t)), ego)
        assert result.state is TrackState.TRACKING
        assert iou(result.box, scene.truth(t)) > 0.5, t


def test_colour_tracker_alone_loses_him_at_dusk() -> None:
    """What the switch is for: the colour model learned by day does not see him at night."""
    scene = Scene(velocity=(2.0, 0.5))
    tracker = make_tracker(TrackerConfig(kind="color"))
    tracker.init(scene.frame(0), scene.truth(0))
    for t in range(1, 20):
        tracker.update(scene.frame(t))
    states = [tracker.update(_grey(scene.frame(t))).state for t in range(20, 60)]
    assert TrackState.TRACKING not in states[5:]


def test_no_switch_while_the_target_is_out_of_sight() -> None:
    """Dusk while he is gone: no model is learned on a coasting box; the next init switches."""
    scene = Scene(velocity=(2.0, 0.5), vanish_after=15)
    tracker = _auto()
    tracker.init(scene.frame(0), scene.truth(0))
    for t in range(1, 25):
        result = tracker.update(scene.frame(t))
    assert result.state is not TrackState.TRACKING
    for t in range(25, 35):
        result = tracker.update(_grey(scene.frame(t)))
        assert tracker.kind == "color"
    back = Scene(velocity=(2.0, 0.5))
    log = io.StringIO()
    configure_logging(level="info", fmt="json", stream=log)
    tracker.init(_grey(back.frame(40)), back.truth(40))
    assert tracker.kind == "rf"
    events = [json.loads(line) for line in log.getvalue().splitlines()]
    assert [(e["event"], e["kind"], e["reason"]) for e in events] == [
        ("tracker_switched", "rf", "init")
    ]
    assert tracker.update(_grey(back.frame(41))).state is TrackState.TRACKING


def test_switch_after_a_zoom_step_starts_on_the_zoomed_box() -> None:
    """A zoom step between the last colour frame and the first grey one."""
    scene = Scene(start=(140.0, 80.0, 24.0, 60.0), velocity=(0.0, 0.0))
    tracker = _auto()
    tracker.init(scene.frame(0), scene.truth(0))
    for t in range(1, 10):
        tracker.update(scene.frame(t))
    centre = (160.0, 120.0)
    tracker.rescale(1.5, centre)
    x, y, w, h = scene.truth(10)
    zoomed = (
        centre[0] + (x - centre[0]) * 1.5,
        centre[1] + (y - centre[1]) * 1.5,
        w * 1.5,
        h * 1.5,
    )
    frame = scene.frame(10)
    # the same scene 1.5 x larger about the centre
    m = np.array([[1.5, 0.0, centre[0] * -0.5], [0.0, 1.5, centre[1] * -0.5]])
    big = cv2.warpAffine(frame, m, (frame.shape[1], frame.shape[0]))
    result = tracker.update(_grey(np.asarray(big, np.uint8)))
    assert tracker.kind == "rf"
    assert iou(result.box, zoomed) > 0.6
