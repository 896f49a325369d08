"""`ptzd sim` from the command line: the summary on stdout, `--view` video, log lines bound
to the camera name."""

from __future__ import annotations

import json
import subprocess
import sys
from pathlib import Path

import cv2
import numpy as np
import pytest

pytest.importorskip("ptzd.sim.scene", reason="the synthetic scene is not available")


def test_sim_view_video_and_camera_bound_logs(tmp_path: Path) -> None:
    view = tmp_path / "out" / "view.mp4"
    proc = subprocess.run(
        [sys.executable, "-m", "ptzd", "--log-format", "json", "sim", "--scene", "synthetic:1",
         "--duration", "1.5", "--virtual-clock", "--camera-name", "porch",
         "--view", str(view), "--record", str(tmp_path / "rec")],
        capture_output=True, timeout=120, check=False,
    )  # fmt: skip
    assert proc.returncode == 0, proc.stderr.decode()
    summary = json.loads(proc.stdout)
    events = [json.loads(line) for line in proc.stderr.decode().splitlines()]
    assert events and all(e["camera"] == "porch" for e in events)

    capture = cv2.VideoCapture(str(view))
    frames = []
    while True:
        ok, image = capture.read()
        if not ok:
            break
        frames.append(image)
    capture.release()
    assert len(frames) == summary["frames_rendered"] > 10
    # the tracker's box (green while tracking) is drawn where track.jsonl says it was
    track = json.loads((tmp_path / "rec" / "track.jsonl").read_text().splitlines()[-1])
    assert track["state"] == "tracking"
    x, y, w, _ = (round(v) for v in track["box"])
    top_edge = frames[-1][max(y, 0), max(x, 0) + 2 : x + w - 2].astype(int)
    b, g, r = top_edge[:, 0], top_edge[:, 1], top_edge[:, 2]
    assert np.mean((g > 150) & (r < 90) & (b < 90)) > 0.8


def test_sim_follows_a_named_synthetic_walker_and_draws_searching_frames(tmp_path: Path) -> None:
    """`--target` alone on a synthetic scene (it carries its own ground truth); with
    `--acquire` the first frames have no box, and `--view` draws them without one."""
    view = tmp_path / "view.mp4"
    proc = subprocess.run(
        [sys.executable, "-m", "ptzd", "sim", "--scene", "synthetic:0", "--target", "6",
         "--acquire", "--duration", "1", "--virtual-clock", "--view", str(view),
         "--record", str(tmp_path / "rec")],
        capture_output=True, timeout=120, check=False,
    )  # fmt: skip
    assert proc.returncode == 0, proc.stderr.decode()[-2000:]
    report = json.loads((tmp_path / "rec" / "report.json").read_text())
    assert report["target"] == 6 and report["acquire"]
    first = json.loads((tmp_path / "rec" / "track.jsonl").read_text().splitlines()[0])
    assert first["box"] is None and first["state"] == "searching"
    capture = cv2.VideoCapture(str(view))
    count = int(capture.get(cv2.CAP_PROP_FRAME_COUNT))
    capture.release()
    assert count == report["frames_rendered"] > 10
