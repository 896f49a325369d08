"""`ptzd track` on a real encoded video: output contract, overlay, bad inputs."""

from __future__ import annotations

import json
import subprocess
import sys
from pathlib import Path

import cv2
import pytest

from ptzd.vision.features import to_bgr, to_grey
from tests.vision_helpers import Scene, iou

FRAMES = 30


@pytest.fixture(scope="module")
def video(tmp_path_factory: pytest.TempPathFactory) -> tuple[Path, Scene]:
    scene = Scene(velocity=(2.0, 0.5))
    path = tmp_path_factory.mktemp("track") / "scene.avi"
    writer = cv2.VideoWriter(
        str(path), cv2.VideoWriter.fourcc(*"MJPG"), 10.0, (scene.width, scene.height)
    )
    assert writer.isOpened()
    for t in range(FRAMES):
        writer.write(scene.frame(t))
    writer.release()
    return path, scene


def _ptzd(*args: str) -> subprocess.CompletedProcess[str]:
    return subprocess.run(
        [sys.executable, "-m", "ptzd", *args], capture_output=True, text=True, timeout=120
    )


def _box(scene: Scene, t: int) -> str:
    return ",".join(f"{v:g}" for v in scene.truth(t))


def test_track_writes_every_frame_from_start_to_end(video, tmp_path: Path) -> None:
    path, scene = video
    out, overlay = tmp_path / "out.json", tmp_path / "overlay.mp4"
    proc = _ptzd(
        "track", str(path), "--init", _box(scene, 5), "--start", "5", "--end", "20",
        "--out", str(out), "--overlay", str(overlay), "--seed", "3",
    )  # fmt: skip
    assert proc.returncode == 0, proc.stderr
    data = json.loads(out.read_text())
    assert set(data) >= {"boxes", "fps", "params"}
    assert list(data["boxes"]) == [str(t) for t in range(5, 21)]  # N..M inclusive
    assert data["boxes"]["5"] == pytest.approx(list(scene.truth(5)), abs=0.01)
    for t in range(6, 21):
        assert iou(tuple(data["boxes"][str(t)]), scene.truth(t)) > 0.5
    assert data["fps"] > 0
    assert data["params"]["config"]["seed"] == 3
    capture = cv2.VideoCapture(str(overlay))
    assert int(capture.get(cv2.CAP_PROP_FRAME_COUNT)) == 16
    capture.release()


def test_auto_tracks_through_dusk_in_an_encoded_video(tmp_path: Path) -> None:
    """A day/night camera's video going grey halfway (MJPEG-coded, so the grey frames carry
    the codec's chroma rounding): `--tracker auto` hands over to rf and stays on him."""
    scene = Scene(velocity=(2.0, 0.5))
    path = tmp_path / "dusk.avi"
    writer = cv2.VideoWriter(
        str(path), cv2.VideoWriter.fourcc(*"MJPG"), 10.0, (scene.width, scene.height)
    )
    for t in range(FRAMES):
        frame = scene.frame(t)
        writer.write(to_bgr(to_grey(frame)) if t >= 15 else frame)
    writer.release()
    out = tmp_path / "out.json"
    proc = _ptzd("track", str(path), "--init", _box(scene, 0), "--tracker", "auto",
                 "--out", str(out))  # fmt: skip
    assert proc.returncode == 0, proc.stderr
    assert "tracker_switched" in proc.stdout + proc.stderr
    boxes = json.loads(out.read_text())["boxes"]
    for t in range(1, FRAMES):
        assert iou(tuple(boxes[str(t)]), scene.truth(t)) > 0.5, t


def test_track_runs_to_the_last_frame_without_end(video, tmp_path: Path) -> None:
    path, scene = video
    out = tmp_path / "out.json"
    proc = _ptzd("track", str(path), "--init", _box(scene, 0), "--out", str(out))
    assert proc.returncode == 0, proc.stderr
    boxes = json.loads(out.read_text())["boxes"]
    assert list(boxes) == [str(t) for t in range(FRAMES)]


@pytest.mark.parametrize(
    "extra, message",
    [
        (["--init", "900,900,20,40"], "outside"),
        (["--init", "10,10,0,40"], "positive width"),
        (["--init", "10,10,20"], "four numbers"),
        (["--init", "a,b,c,d"], "X,Y,W,H"),
        (["--init", "10,10,20,40", "--start", "500"], "beyond the end"),
        (["--init", "10,10,20,40", "--start", "9", "--end", "3"], "before --start"),
    ],
)
def test_bad_inputs_exit_2_with_one_line(video, tmp_path: Path, extra, message) -> None:
    path, _ = video
    out = tmp_path / "out.json"
    proc = _ptzd("track", str(path), *extra, "--out", str(out))
    assert proc.returncode == 2
    lines = proc.stderr.strip().splitlines()
    assert len(lines) == 1 and message in lines[0], proc.stderr
    assert not out.exists()


def test_unreadable_video_exits_2(tmp_path: Path) -> None:
    junk = tmp_path / "junk.avi"
    junk.write_bytes(b"this is not a video" * 100)
    for path in (junk, tmp_path / "missing.avi"):
        proc = _ptzd("track", str(path), "--init", "1,1,10,10", "--out", str(tmp_path / "o.json"))
        assert proc.returncode == 2
        assert "cannot read video" in proc.stderr


def test_track_accepts_the_simulator_scene(tmp_path: Path) -> None:
    from ptzd.sim.sources import open_wide_source

    truth = open_wide_source("synthetic:1").ground_truth
    assert truth is not None
    # a walker fully in view for 15 frames
    track = next(
        frames
        for frames in truth.tracks.values()
        if len(frames) > 40 and all(frames[f][2] > 15 for f in sorted(frames)[20:35])
    )
    first = sorted(track)[20]
    box = ",".join(f"{v:g}" for v in track[first])
    out = tmp_path / "out.json"
    end = first + 10
    proc = _ptzd(
        "track", "synthetic:1", "--init", box, "--start", str(first), "--end", str(end),
        "--out", str(out),
    )  # fmt: skip
    assert proc.returncode == 0, proc.stderr
    boxes = json.loads(out.read_text())["boxes"]
    assert list(boxes) == [str(t) for t in range(first, end + 1)]
    proc = _ptzd("track", "synthetic:x", "--init", box, "--out", str(out))
    assert proc.returncode == 2


def test_a_box_partly_off_the_left_edge_is_read_as_the_init_value(video, tmp_path: Path) -> None:
    """`--init -5,...` (argparse would take it for an option) tracks from the clipped box."""
    path, _ = video
    out = tmp_path / "out.json"
    proc = _ptzd("track", str(path), "--init", "-5,10,20,30", "--end", "2", "--out", str(out))
    assert proc.returncode == 0, proc.stderr
    boxes = json.loads(out.read_text())["boxes"]
    assert boxes["0"] == pytest.approx([0.0, 10.0, 15.0, 30.0])  # clipped to the frame
    assert list(boxes) == ["0", "1", "2"]


def test_box_values_with_a_minus_are_attached_to_their_option() -> None:
    from ptzd.cli import attach_negative_boxes

    assert attach_negative_boxes(["track", "v", "--init", "-5,1,2,3", "--end", "2"]) == [
        "track", "v", "--init=-5,1,2,3", "--end", "2"
    ]  # fmt: skip
    untouched = ["track", "v", "--init", "5,1,2,3", "--out", "-"]
    assert attach_negative_boxes(untouched) == untouched
    assert attach_negative_boxes(["track", "--init", "--out", "x"]) == [
        "track",
        "--init",
        "--out",
        "x",
    ]
    assert attach_negative_boxes(["track", "--init"]) == ["track", "--init"]
