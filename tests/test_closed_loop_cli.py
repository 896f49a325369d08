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


def test_sim_can_start_at_the_widest_pointed_at_the_target(tmp_path: Path) -> None:
    """`[sim] start_hfov`: the dome starts at that FOV (as the soak's does), still looking at
    the target; by default the target is a third of the view high."""
    config = tmp_path / "wide.toml"
    config.write_text("[sim]\nstart_hfov = 60.0\n")

    def first_view(*extra: str) -> tuple[dict[str, float], list[float]]:
        rec = tmp_path / ("rec" + "".join(extra).replace("/", "_"))
        proc = subprocess.run(
            [sys.executable, "-m", "ptzd", "sim", "--scene", "synthetic:0", "--target", "6",
             "--duration", "0.3", "--virtual-clock", "--record", str(rec), *extra],
            capture_output=True, timeout=120, check=False,
        )  # fmt: skip
        assert proc.returncode == 0, proc.stderr.decode()[-2000:]
        camera = json.loads((rec / "camera.jsonl").read_text().splitlines()[0])
        truth = json.loads((rec / "groundtruth_view.jsonl").read_text().splitlines()[0])
        return camera, truth["boxes"]["6"]

    wide, box = first_view("--config", str(config))
    assert wide["hfov"] == pytest.approx(60.0)
    assert abs(box[0] + box[2] / 2 - 320) < 3 and abs(box[1] + box[3] / 2 - 240) < 3
    assert box[3] < 480 / 6  # a small figure at the widest
    near, box = first_view()
    assert near["hfov"] < 40.0 and box[3] == pytest.approx(480 / 3, rel=0.1)
    # and from a pose of its own (a soak's, to play one of its selections again): the
    # target off-centre, right of and below the middle
    config.write_text(
        "[sim]\nstart_hfov = 60.0\n"
        f"start_pan = {wide['pan'] - 10.0}\nstart_tilt = {wide['tilt'] + 5.0}\n"
    )
    posed, box = first_view("--config", str(config), "--duration", "0.2")
    assert posed["pan"] == pytest.approx(wide["pan"] - 10.0)
    assert posed["tilt"] == pytest.approx(wide["tilt"] + 5.0)
    assert box[0] + box[2] / 2 > 320 + 50 and box[1] + box[3] / 2 > 240 + 20


def test_a_named_synthetic_walker_is_taken_up_once_fully_in_view(tmp_path: Path) -> None:
    """Synthetic:0's walker 4 enters at the wide image's bottom edge (his first box is a
    sliver of his head); `--target 4` starts where he is first well in view, as an operator
    would select him."""
    from ptzd.closed_loop import first_well_visible, fully_visible
    from ptzd.sim.sources import open_wide_source

    gt = open_wide_source("synthetic:0").ground_truth
    assert gt is not None
    start = first_well_visible(gt, 4)
    assert start > min(gt.tracks[4]) and fully_visible(gt, 4, start)
    rec = tmp_path / "rec"
    proc = subprocess.run(
        [sys.executable, "-m", "ptzd", "sim", "--scene", "synthetic:0", "--target", "4",
         "--duration", "0.2", "--virtual-clock", "--record", str(rec)],
        capture_output=True, timeout=120, check=False,
    )  # fmt: skip
    assert proc.returncode == 0, proc.stderr.decode()[-2000:]
    first = json.loads((rec / "camera.jsonl").read_text().splitlines()[0])
    assert first["video_frame"] == start
