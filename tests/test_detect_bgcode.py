"""The background + codebook detector stage by stage, non-human rejection, detector choice."""

from __future__ import annotations

import math

import cv2
import numpy as np
import pytest

from ptzd.config import validate_config
from ptzd.vision.detect.background import ForegroundMasks, RunningAverageBackground
from ptzd.vision.detect.bgcode import BackgroundCodebookDetector, candidate_regions
from ptzd.vision.detect.codebook import Codebook, train_codebook
from ptzd.vision.detect.config import BgCodeConfig, DetectorConfig
from ptzd.vision.detect.factory import make_detector
from ptzd.vision.detect.figures import draw_walker, noisy_background, walker_silhouette
from ptzd.vision.detect.hog import DetectorUnavailableError, HogPeopleDetector, hog_available
from ptzd.vision.detect.shape import full_profile, normalise_silhouette
from ptzd.vision.detect.types import iou

W, H = 320, 240


@pytest.fixture(scope="module")
def walker_book() -> Codebook:
    """A codebook of the procedural walker at many sizes and gait phases, each silhouette
    cut by the detector's own region extraction (dilation included)."""
    kernel = cv2.getStructuringElement(cv2.MORPH_ELLIPSE, (5, 5))
    profiles = []
    for h in (50, 70, 90, 120):
        for p in np.linspace(0, 2 * math.pi, 16, endpoint=False):
            for f in (1, -1):
                raw = np.pad(walker_silhouette(h, p, facing=f), 8).astype(np.uint8) * 255
                masks = ForegroundMasks(
                    raw=raw, dilated=np.asarray(cv2.dilate(raw, kernel), np.uint8)
                )
                (region,) = candidate_regions(masks, min_area=50)
                profiles.append(full_profile(normalise_silhouette(region.silhouette)))
    return train_codebook(np.stack(profiles), size=16, seed=0, margin=1.3)


def _frames(draw, n: int = 40, seed: int = 0):
    """n frames: a fixed noisy background with draw(frame, i) applied to each."""
    rng = np.random.default_rng(seed)
    base = noisy_background(W, H, rng, noise=0.0)
    for i in range(n):
        frame = base.copy()
        box = draw(frame, i)
        noise = rng.normal(0, 2.0, frame.shape)
        yield np.clip(frame + noise, 0, 255).astype(np.uint8), box


def _walker(frame: np.ndarray, i: int):
    """Walks in after the background has warmed up on the empty view (frame 12)."""
    if i < 12:
        return None
    return draw_walker(frame, 3 * i, 60, 90, i * 0.5, (235, 235, 235))


def test_eq1_running_average_outside_active_pixels() -> None:
    cfg = BgCodeConfig(alpha=0.8, warmup_frames=1)
    model = RunningAverageBackground(cfg)
    first = np.full((20, 20), 100, np.uint8)
    assert model.apply(first) is None  # the first frame starts the model
    second = np.full((20, 20), 110, np.uint8)  # below ths=25: not active, plain eq. 1
    masks = model.apply(second)
    assert masks is not None and not masks.raw.any()
    bg = model.background
    assert bg is not None and int(bg[5, 5]) == round(0.8 * 100 + 0.2 * 110)


def test_eq3_threshold_and_dilation_give_one_region() -> None:
    cfg = BgCodeConfig(warmup_frames=1, dilate_px=2, min_area=10)
    model = RunningAverageBackground(cfg)
    empty = np.full((60, 60), 50, np.uint8)
    model.apply(empty)
    model.apply(empty)
    frame = empty.copy()
    frame[10:40, 20:30] = 50 + 25  # exactly ths -> foreground (>=)
    frame[10:40, 24] = 50 + 24  # a one-pixel crack below ths, closed by dilation
    masks = model.apply(frame)
    assert masks is not None
    assert masks.raw[20, 24] == 0 and masks.raw[20, 23] == 255
    regions = candidate_regions(masks, min_area=10)
    assert len(regions) == 1
    assert (regions[0].x, regions[0].y, regions[0].w, regions[0].h) == (20, 10, 10, 30)


def test_walking_person_is_detected(walker_book: Codebook) -> None:
    det = BackgroundCodebookDetector(BgCodeConfig(), walker_book)
    hits = 0
    for i, (frame, box) in enumerate(_frames(_walker)):
        found = det.detect(frame)
        if i >= 14:
            assert len(found) <= 1
            hits += any(iou(d.box, box) >= 0.5 for d in found)
            assert all(0.0 <= d.score <= 1.0 and d.label == "person" for d in found)
    assert hits >= 24  # of 26 frames with the walker fully in view


def _car(frame: np.ndarray, i: int):
    x = 10 + 6 * i
    cv2.rectangle(frame, (x, 150), (x + 90, 190), (150, 40, 40), -1)
    cv2.rectangle(frame, (x + 15, 130), (x + 70, 152), (120, 30, 30), -1)
    return (x, 130, 90, 60)


def _tree(frame: np.ndarray, i: int):
    sway = int(8 * math.sin(i * 0.8))
    cv2.ellipse(frame, (160 + sway, 70), (35, 50), 0, 0, 360, (40, 120, 40), -1)
    cv2.rectangle(frame, (154, 110), (166, 200), (30, 60, 90), -1)
    return (125, 20, 70, 180)


def _tall_box(frame: np.ndarray, i: int):
    if i < 12:  # enters after warm-up, like the walker
        return None
    x = 4 * i
    cv2.rectangle(frame, (x, 40), (x + 30, 160), (250, 250, 250), -1)  # a person-sized box
    return (x, 40, 30, 120)


@pytest.mark.parametrize("draw", [_car, _tree, _tall_box], ids=["car", "tree", "tall_box"])
def test_non_human_motion_is_rejected(walker_book: Codebook, draw) -> None:
    det = BackgroundCodebookDetector(BgCodeConfig(), walker_book)
    found = [d for frame, _ in _frames(draw) for d in det.detect(frame)]
    assert found == []


def test_global_lighting_change_rebuilds_and_detects_nothing(walker_book: Codebook) -> None:
    det = BackgroundCodebookDetector(BgCodeConfig(), walker_book)
    found = []
    for i, (frame, _) in enumerate(_frames(lambda f, i: None, n=40)):
        lit = cv2.convertScaleAbs(frame, alpha=1.0, beta=60 if i >= 20 else 0)
        found += det.detect(lit)
    assert found == []
    assert det.model.rebuilds == 1


def test_camera_motion_suspends_and_resets_the_model(walker_book: Codebook) -> None:
    cfg = BgCodeConfig(warmup_frames=5)
    det = BackgroundCodebookDetector(cfg, walker_book)
    frames = list(_frames(_walker, n=40))
    for frame, _ in frames[:15]:
        det.detect(frame)
    assert det.model.frames_since_reset == 15
    # moving: nothing learnt, nothing reported, even with a person in view
    for frame, _ in frames[15:20]:
        assert det.detect(frame, camera_moving=True) == []
    assert det.model.frames_since_reset == 15
    # stopped: a new background, and warm-up before anything is reported
    outputs = [det.detect(frame) for frame, _ in frames[20:40]]
    assert all(out == [] for out in outputs[:5])
    assert det.model.frames_since_reset == 20
    assert any(outputs[5:])


def test_detector_choice_from_config() -> None:
    config = validate_config({"detector": {"kind": "bgcode"}}, environ={})
    det = make_detector(config.detector)
    assert isinstance(det, BackgroundCodebookDetector)
    assert det.threshold == Codebook.load_default().threshold
    tuned = validate_config(
        {"detector": {"bgcode": {"distortion_threshold": 12.5}}}, environ={}
    ).detector
    tuned_det = make_detector(tuned)
    assert isinstance(tuned_det, BackgroundCodebookDetector) and tuned_det.threshold == 12.5
    hog = DetectorConfig(kind="hog")
    if hog_available():
        assert isinstance(make_detector(hog), HogPeopleDetector)
    else:  # OpenCV 5 wheels ship no HOG: a clear, typed error instead of a crash later
        with pytest.raises(DetectorUnavailableError) as info:
            make_detector(hog)
        assert info.value.kind == "hog"
    with pytest.raises(Exception, match="aspect_min"):
        validate_config({"detector": {"bgcode": {"aspect_min": 6.0}}}, environ={})


def test_detects_people_of_the_synthetic_scene() -> None:
    """End to end on the simulator's scene with the shipped codebook (held-out seed)."""
    from ptzd.sim.scene import SceneParams, SceneSource
    from ptzd.vision.detect.evaluate import DetectionScore

    src = SceneSource(1, params=SceneParams(width=640, height=480, frame_count=90))
    truth = src.ground_truth
    det = make_detector(DetectorConfig())
    score = DetectionScore()
    for i in range(90):
        found = det.detect(src.read(i))
        if i >= 30:
            boxes = truth.boxes_at(i)
            vis = [truth.visibility.get(k, {}).get(i, 1.0) for k in boxes]
            score.add_frame(
                i, [d.box for d in found], list(boxes.values()), src.size, visibility=vis
            )
    assert score.true_positives > 60
    assert score.recall >= 0.85 and score.precision >= 0.85, (score.recall, score.precision)


def test_still_or_moving_routes_by_camera_state(walker_book: Codebook) -> None:
    from ptzd.vision.detect.factory import StillOrMovingDetector

    still = BackgroundCodebookDetector(BgCodeConfig(warmup_frames=3), walker_book)
    moving = BackgroundCodebookDetector(BgCodeConfig(warmup_frames=3), walker_book)
    combined = StillOrMovingDetector(still, moving)
    frames = [frame for frame, _ in _frames(_walker, n=20)]
    for frame in frames[:5]:
        combined.detect(frame)
    assert still.model.frames_since_reset == 5 and moving.model.frames_since_reset == 0
    for frame in frames[5:8]:
        combined.detect(frame, camera_moving=True)
    assert still.model.frames_since_reset == 5  # frozen while moving
    combined.detect(frames[8])
    assert still.model.frames_since_reset == 1  # a new background after the move
    assert combined.name == "bgcode+bgcode"
