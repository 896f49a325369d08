"""`ptzd detect` and `ptzd codebook` end to end on real decoded video and real files."""

from __future__ import annotations

import json
from pathlib import Path

import cv2
import pytest

from ptzd.cli import main
from ptzd.vision.detect.codebook import Codebook
from ptzd.vision.detect.figures import FigureScene


def _video(path: Path, frames: int = 40) -> FigureScene:
    scene = FigureScene(5, width=320, height=240, frame_count=frames, walkers=2)
    writer = cv2.VideoWriter(str(path), cv2.VideoWriter.fourcc(*"MJPG"), scene.fps, scene.size)
    assert writer.isOpened()
    for i in range(frames):
        writer.write(scene.read(i))
    writer.release()
    return scene


def test_detect_writes_every_frame_and_an_overlay(tmp_path: Path) -> None:
    video = tmp_path / "walk.avi"
    _video(video)
    out = tmp_path / "dets.json"
    overlay = tmp_path / "overlay.avi"
    code = main(["detect", str(video), "--out", str(out), "--overlay", str(overlay)])
    assert code == 0
    doc = json.loads(out.read_text())
    assert set(doc) == {"frames"}
    assert sorted(doc["frames"], key=int) == [str(i) for i in range(40)]
    for rows in doc["frames"].values():
        for row in rows:
            assert len(row) == 5 and row[2] > 0 and row[3] > 0 and 0 <= row[4] <= 1
    cap = cv2.VideoCapture(str(overlay))
    assert int(cap.get(cv2.CAP_PROP_FRAME_COUNT)) == 40
    cap.release()


def test_detect_bad_input_is_a_usage_error(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    assert main(["detect", str(tmp_path / "nope.avi"), "--out", str(tmp_path / "x.json")]) == 2
    bad = tmp_path / "bad.npz"
    bad.write_text("junk")
    video = tmp_path / "walk.avi"
    _video(video, frames=3)
    code = main(["detect", str(video), "--codebook", str(bad), "--out", str(tmp_path / "x.json")])
    assert code == 2
    assert "codebook" in capsys.readouterr().err


def test_codebook_train_records_how_to_regenerate(tmp_path: Path) -> None:
    out = tmp_path / "cb.npz"
    args = ["codebook", "train", "--source", "figures:3", "--max-frames", "60", "--size", "4"]
    assert main([*args, "--out", str(out)]) == 0
    book = Codebook.load(out)
    assert book.codewords.shape == (4, 30)
    provenance = json.loads(book.provenance)
    assert provenance["command"].startswith("ptzd codebook train --source figures:3 --size 4")
    assert provenance["silhouettes"]["figures:3"] >= 4
    assert main(["codebook", "train", "--out", str(out)]) == 2  # no source given
    assert main(["codebook", "show", str(out)]) == 0
