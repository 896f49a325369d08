"""Tracking metrics against hand-computed examples."""

from __future__ import annotations

import json
import math
from pathlib import Path

import numpy as np
import pytest

from ptzd.metrics import (
    IOU_THRESHOLDS,
    TrackOutputError,
    center_error,
    iou,
    load_track_output,
    precision_at,
    score_sequence,
    success_curve,
)
from ptzd.sim.groundtruth import load_ground_truth


def test_thresholds_are_otb_21_steps() -> None:
    assert len(IOU_THRESHOLDS) == 21
    assert IOU_THRESHOLDS[0] == 0.0 and IOU_THRESHOLDS[-1] == 1.0
    assert IOU_THRESHOLDS[3] == 0.15


def test_iou_hand_computed() -> None:
    # 10x10 boxes shifted by 5 px: intersection 5*10 = 50, union 100 + 100 - 50 = 150
    assert iou((0, 0, 10, 10), (5, 0, 10, 10)) == pytest.approx(1 / 3)
    # box inside a box: 4*4 / (10*10)
    assert iou((0, 0, 10, 10), (3, 3, 4, 4)) == pytest.approx(0.16)
    assert iou((0, 0, 10, 10), (0, 0, 10, 10)) == 1.0
    # touching edges do not overlap
    assert iou((0, 0, 10, 10), (10, 0, 10, 10)) == 0.0
    assert iou(None, (0, 0, 10, 10)) == 0.0
    assert iou((0, 0, 10, 10), None) == 0.0


def test_center_error_hand_computed() -> None:
    # centres (5, 5) and (8, 9): a 3-4-5 triangle
    assert center_error((0, 0, 10, 10), (3, 4, 10, 10)) == pytest.approx(5.0)
    # same centre, different sizes
    assert center_error((0, 0, 10, 10), (-5, -5, 20, 20)) == 0.0
    assert math.isinf(center_error(None, (0, 0, 1, 1)))


def test_success_curve_and_auc_hand_computed() -> None:
    gt = {0: (0.0, 0.0, 10.0, 10.0), 1: (0.0, 0.0, 10.0, 10.0), 2: (0.0, 0.0, 10.0, 10.0),
          3: (0.0, 0.0, 10.0, 10.0)}  # fmt: skip
    pred = {
        0: (0.0, 0.0, 10.0, 10.0),  # IoU 1, centre error 0
        1: (5.0, 0.0, 10.0, 10.0),  # IoU 1/3, centre error 5
        2: (30.0, 0.0, 10.0, 10.0),  # IoU 0, centre error 30
        3: None,  # lost: IoU 0, centre error infinite
    }
    score = score_sequence(pred, gt)
    # IoU > t: t in 0..0.30 (7 thresholds) -> 2/4; 0.35..0.95 (13) -> 1/4; t = 1 -> 0
    expected = [0.5] * 7 + [0.25] * 13 + [0.0]
    assert score.success == pytest.approx(expected)
    assert score.auc == pytest.approx((7 * 0.5 + 13 * 0.25) / 21)  # 0.3214...
    assert score.precision_20 == pytest.approx(0.5)  # errors 0, 5 <= 20; 30, inf are not
    assert score.lost_frames == 1
    assert score.frames == 4
    assert score.mean_iou == pytest.approx((1 + 1 / 3) / 4)


def test_frames_without_ground_truth_are_skipped_and_missing_predictions_are_lost() -> None:
    gt = {10: (0.0, 0.0, 10.0, 10.0), 12: (0.0, 0.0, 10.0, 10.0)}
    pred = {
        10: (0.0, 0.0, 10.0, 10.0),
        11: None,  # no ground truth on frame 11: ignored although null
        13: (500.0, 500.0, 1.0, 1.0),  # no ground truth: ignored although wrong
    }  # frame 12 missing from the output: counts as lost
    score = score_sequence(pred, gt)
    assert score.frames == 2
    assert score.lost_frames == 1
    assert score.precision_20 == pytest.approx(0.5)
    assert score.success[0] == pytest.approx(0.5)


def test_range_restricts_scored_frames() -> None:
    gt = dict.fromkeys(range(10), (0.0, 0.0, 10.0, 10.0))
    box: tuple[float, float, float, float] | None = (0.0, 0.0, 10.0, 10.0)
    pred = dict.fromkeys(range(3, 6), box)
    score = score_sequence(pred, gt, start=3, end=5)
    assert score.frames == 3
    assert score.lost_frames == 0
    assert score.auc == pytest.approx(20 / 21)  # IoU 1 succeeds at every threshold but 1
    assert score_sequence(pred, gt).lost_frames == 7


def test_empty_sequence_scores_zero() -> None:
    score = score_sequence({}, {})
    assert score.frames == 0 and score.auc == 0.0 and score.precision_20 == 0.0
    assert success_curve(np.array([])).shape == (21,)


def test_precision_radius_is_inclusive() -> None:
    assert precision_at(np.array([20.0, 20.000001, math.inf])) == pytest.approx(1 / 3)
    assert precision_at(np.array([0.5, 9.0]), radius=5.0) == 0.5


def test_load_track_output(tmp_path: Path) -> None:
    path = tmp_path / "out.json"
    path.write_text(json.dumps({"boxes": {"4": [1, 2, 3, 4], "5": None}, "fps": 812.5}))
    assert load_track_output(path) == {4: (1.0, 2.0, 3.0, 4.0), 5: None}


@pytest.mark.parametrize(
    ("content", "reason"),
    [
        ("{", "not JSON"),
        ('{"fps": 1}', '"boxes"'),
        ('{"boxes": {"x": [1, 2, 3, 4]}}', "not an integer"),
        ('{"boxes": {"1": [1, 2, 3]}}', "expected [x, y, w, h]"),
        ('{"boxes": {"1": [1, 2, 0, 4]}}', "w, h > 0"),
        ('{"boxes": {"-1": [1, 2, 3, 4]}}', "negative"),
    ],
)
def test_load_track_output_rejects_bad_files(tmp_path: Path, content: str, reason: str) -> None:
    path = tmp_path / "bad.json"
    path.write_text(content)
    with pytest.raises(TrackOutputError) as info:
        load_track_output(path)
    assert reason in info.value.reason
    assert info.value.path == str(path)


def test_load_track_output_missing_file(tmp_path: Path) -> None:
    with pytest.raises(TrackOutputError, match="cannot read"):
        load_track_output(tmp_path / "nope.json")


def test_scores_a_track_of_a_ground_truth_file(tmp_path: Path) -> None:
    """The benchmark's path: a ground-truth file (shared format) and a `ptzd track` output."""
    gt_path = tmp_path / "gt.json"
    gt_path.write_text(
        json.dumps(
            {
                "size": [768, 576],
                "fps": 10,
                "tracks": [{"id": 7, "frames": {"3": [100, 50, 20, 40], "4": [104, 50, 20, 40]}}],
            }
        )
    )
    out_path = tmp_path / "out.json"
    # frame 3 exact, frame 4 shifted by 10 px: IoU (10*40) / (2*800 - 400) = 1/3, error 10
    out_path.write_text(json.dumps({"boxes": {"3": [100, 50, 20, 40], "4": [114, 50, 20, 40]}}))
    score = score_sequence(
        load_track_output(out_path), load_ground_truth(gt_path).tracks[7], start=3, end=4
    )
    assert score.precision_20 == 1.0
    assert score.mean_iou == pytest.approx((1 + 1 / 3) / 2)
    assert score.lost_frames == 0


def test_committed_vtest_annotations_follow_the_conventions(repo_root: Path) -> None:
    """bench/annotations: >= 4 tracks of 50-300 consecutive frames, boxes inside 768x576."""
    paths = sorted((repo_root / "bench" / "annotations").glob("vtest_*.json"))
    assert len(paths) >= 4
    for path in paths:
        gt = load_ground_truth(path, expected_size=(768, 576))
        assert gt.fps == 10.0
        for boxes in gt.tracks.values():
            frames = sorted(boxes)
            assert 50 <= len(frames) <= 300, path.name
            assert frames == list(range(frames[0], frames[-1] + 1)), path.name
            assert frames[-1] < 795
            for x, y, w, h in boxes.values():
                assert w > 0 and h > 0
                assert x >= 0 and y >= 0 and x + w <= 768 and y + h <= 576, path.name
