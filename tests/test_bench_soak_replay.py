"""bench/soak_replay.py: a soak's selections found in its records and played again in process."""

from __future__ import annotations

import json
from pathlib import Path
from typing import Any

import pytest

from bench.soak_replay import Selection, main, settled_centring, soak_selections, walker_truth
from ptzd.sim.groundtruth import Box, GroundTruth

# walker 19 of synthetic:0 as a 1-hour soak's operator boxed him at scene frame 1009, with
# the soak dome's pose then (its sim/camera.jsonl)
POSE = {"pan": -6.2972, "tilt": -15.95, "hfov": 60.0}


def fake_soak(root: Path, *, frame: int = 13009, walker: int = 19, scene_frame: int = 1009) -> Path:
    """The records `soak_selections` reads, as a real-time soak writes them: one selection
    at soak frame `frame`; the dome turned 1 deg a frame until then and stood after."""
    (root / "sim").mkdir(parents=True)
    views, poses = [], []
    for i in range(frame - 3, frame + 3):
        t = round(i * 0.04, 2)
        views.append({"t": t, "frame": i, "video_frame": scene_frame + i - frame, "boxes": {}})
        pan = POSE["pan"] - max(frame - i, 0)
        poses.append({"t": t, "video_frame": scene_frame + i - frame, **POSE, "pan": pan,
                      "width": 640, "height": 480})  # fmt: skip
    (root / "sim" / "groundtruth_view.jsonl").write_text(
        "".join(json.dumps(v) + "\n" for v in views)
    )
    (root / "sim" / "camera.jsonl").write_text("".join(json.dumps(p) + "\n" for p in poses))
    selection = {"t": 600.0, "frame": frame, "walker": str(walker), "waited_s": 0.0}
    centring = {"frame": frame, "walker": str(walker), "frames": 400, "in_view": 1.0,
                "centred": 0.5}  # fmt: skip
    report = {"selections": [selection], "centring": {"selections": [centring]}}
    (root / "report.json").write_text(json.dumps(report))
    return root


def test_a_selection_is_found_with_the_dome_s_pose_at_its_frame(tmp_path: Path) -> None:
    [found] = soak_selections(fake_soak(tmp_path))
    assert found == Selection(13009, 19, 1009, POSE["pan"], POSE["tilt"], POSE["hfov"], 0.5, 1.0)


def test_the_walker_s_truth_starts_at_the_selected_frame() -> None:
    truth = GroundTruth((100, 80), 25.0, tracks={1: {5: (1, 1, 2, 2), 9: (3, 3, 2, 2)},
                                                 2: {5: (0, 0, 1, 1)}})  # fmt: skip
    cut = walker_truth(truth, 1, 6)
    assert cut.tracks == {1: {9: (3, 3, 2, 2)}, 2: {5: (0, 0, 1, 1)}}


def test_a_late_box_starts_later_with_the_box_drawn_before() -> None:
    walked: dict[int, Box] = {5: (1, 1, 2, 2), 6: (2, 1, 2, 2), 7: (3, 1, 2, 2), 8: (4, 1, 2, 2)}
    truth = GroundTruth((100, 80), 25.0, tracks={1: walked})
    late = walker_truth(truth, 1, 5, late=2)
    assert late.tracks == {1: {7: (1, 1, 2, 2), 8: (4, 1, 2, 2)}}


def test_centring_is_counted_after_the_settling_frames() -> None:
    settling: list[dict[str, Any]] = [{"ex": 0.9, "ey": 0.0}] * 3
    after: list[dict[str, Any]] = [
        {"ex": 0.2, "ey": -0.3},
        {"ex": None, "ey": None},
        {"ex": 0.5, "ey": 0.0},
    ]
    per_frame = settling + after
    assert settled_centring(per_frame, 3) == pytest.approx((1 / 3, 2 / 3))
    assert settled_centring(per_frame, 0) == pytest.approx((1 / 6, 5 / 6))


def test_a_selection_replays_from_the_soak_s_pose(tmp_path: Path) -> None:
    soak = fake_soak(tmp_path / "soak")
    out = tmp_path / "replay.json"
    record = tmp_path / "runs"
    argv = [str(soak), "--duration", "4", "--record", str(record), "--out", str(out)]
    assert main(argv) == 0
    [row] = json.loads(out.read_text())["rows"]
    assert (row["frame"], row["walker"], row["video_frame"]) == (13009, 19, 1009)
    assert row["soak_centred"] == 0.5
    # the run's dome started where the soak's stood, on the walker's scene frame
    [run] = list(record.iterdir())
    first = json.loads((run / "camera.jsonl").read_text().splitlines()[0])
    assert first["video_frame"] == 1009
    assert (first["pan"], first["tilt"], first["hfov"]) == pytest.approx(
        (POSE["pan"], POSE["tilt"], POSE["hfov"]), abs=1e-6
    )
    assert 0.0 <= row["centred"] <= row["in_view"] <= 1.0
