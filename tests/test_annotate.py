"""The annotation helper (bench/annotate.py) on synthetic foreground masks."""

from __future__ import annotations

from pathlib import Path

import cv2
import numpy as np

from bench.annotate import Spec, follow, foreground, main
from ptzd.sim.groundtruth import GroundTruth, save_ground_truth


def _mask(boxes: list[tuple[int, int, int, int]]) -> np.ndarray:
    mask = np.zeros((200, 300), np.uint8)
    for x, y, w, h in boxes:
        mask[y : y + h, x : x + w] = 255
    return mask


def test_follows_a_moving_silhouette_exactly() -> None:
    masks = {f: _mask([(20 + 5 * f, 50, 20, 60)]) for f in range(10)}
    spec = Spec("v", 1, 0, 9, {0: (20.0, 50.0, 20.0, 60.0)}, [])
    boxes, source = follow(spec, masks)
    assert boxes[9] == (65.0, 50.0, 20.0, 60.0)
    assert set(source.values()) == {"key", "auto"}


def test_a_merged_silhouette_is_unsure_and_coasts() -> None:
    # frames 0-4 alone; from frame 5 another person touches it on the right: one silhouette
    # 2.5x as wide as the target
    masks = {f: _mask([(20 + 5 * f, 50, 20, 60)] + ([(40 + 5 * f, 50, 30, 60)] if f >= 5 else []))
             for f in range(8)}  # fmt: skip
    spec = Spec("v", 1, 0, 7, {0: (20.0, 50.0, 20.0, 60.0)}, [])
    boxes, source = follow(spec, masks)
    assert [source[f] for f in range(5, 8)] == ["unsure"] * 3
    # coasting at the followed velocity (5 px/frame) with the target's own size
    assert boxes[7][2:] == (20.0, 60.0)
    assert abs(boxes[7][0] - 55.0) < 2.0


def test_a_separate_passer_by_is_ignored() -> None:
    masks = {f: _mask([(20 + 5 * f, 50, 20, 60), (45 + 5 * f, 50, 30, 60)]) for f in range(8)}
    spec = Spec("v", 1, 0, 7, {0: (20.0, 50.0, 20.0, 60.0)}, [])
    boxes, source = follow(spec, masks)
    assert boxes[7] == (55.0, 50.0, 20.0, 60.0)
    assert source[7] == "auto"


def test_keys_override_and_interpolate_linearly() -> None:
    masks = {f: _mask([]) for f in range(11)}  # no foreground at all: only keys count
    spec = Spec(
        "v", 1, 0, 10, {0: (0.0, 0.0, 10.0, 20.0), 10: (100.0, 50.0, 20.0, 40.0)}, [(0, 10)]
    )
    boxes, source = follow(spec, masks)
    assert boxes[5] == (50.0, 25.0, 15.0, 30.0)
    assert source[5] == "interp" and source[10] == "key"


def test_foreground_marks_changed_pixels_only() -> None:
    background = np.full((60, 80, 3), 100, np.uint8)
    frame = background.copy()
    frame[10:40, 20:35] = (100, 100, 200)  # red channel differs by 100
    frame[50:52, 70:72] = 120  # a 2x2 speck of noise below the threshold
    mask = foreground(frame, background)
    assert mask[25, 27] == 255 and mask[5, 5] == 0 and mask[51, 71] == 0


def test_review_draws_a_black_tile_for_a_box_that_has_left_the_image(tmp_path: Path) -> None:
    """A coasting `unsure` box can leave the image; its tile is black, the sheet is made."""
    video = tmp_path / "v.avi"
    writer = cv2.VideoWriter(str(video), cv2.VideoWriter.fourcc(*"MJPG"), 10.0, (160, 120))
    for _ in range(3):
        writer.write(np.full((120, 160, 3), 128, np.uint8))
    writer.release()
    boxes = {
        0: (40.0, 30.0, 20.0, 50.0),
        1: (120.0, 30.0, 20.0, 50.0),
        2: (400.0, 30.0, 20.0, 50.0),
    }
    gt = tmp_path / "gt.json"
    save_ground_truth(GroundTruth((160, 120), 10.0, tracks={1: boxes}), gt)
    out = tmp_path / "sheet.png"
    argv = ["review", str(gt), "--track", "1", "--video", str(video), "--every", "1"]
    assert main([*argv, "--columns", "3", "--out", str(out)]) == 0
    sheet = cv2.imread(str(out))
    assert sheet is not None
    third = sheet.shape[1] // 3
    assert sheet[20:, :third].mean() > 50  # the box in the image: its grey crop
    assert sheet[20:, 2 * third :].mean() < 5  # black (but for the box outline)
