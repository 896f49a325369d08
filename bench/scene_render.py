"""Speed of the wide sources: the synthetic scene's renderer and ground truth, and video reads.

    .venv/bin/python -m bench.scene_render [--frames N] [--repeats R]

Rows (frames per second wall-clock, median over R repeats, one OpenCV thread; the synthetic
rows also show frames per CPU-second of this process, which a busy machine distorts less):
- `synthetic`: `SceneSource.read` at 1280x720 (people, occlusion, lighting, noise),
- `synthetic-thermal`: the thermal variant,
- `synthetic-gt`: `Scene.frame_truth` (boxes + visibility of every person in a frame),
- `video-source`: `VideoFileSource.read` of the same scene written as MJPEG (sequential),
- `videocapture`: a bare `cv2.VideoCapture.read()` loop over that file (the peer: the
  source's overhead over plain decoding),
- `vtest-source` / `vtest-videocapture`: the same two on data/vtest.avi, if present.
Writes bench/results/scene_render.json. The machine is shared by several people: numbers are
noisy; compare rows of one run.
"""

from __future__ import annotations

import argparse
import json
import platform
import statistics
import tempfile
import time
from collections.abc import Callable
from pathlib import Path

import cv2

from ptzd.sim.scene import Scene, SceneParams, SceneSource, write_scene
from ptzd.sim.sources import VideoFileSource

RESULTS = Path(__file__).resolve().parent / "results" / "scene_render.json"
VTEST = Path(__file__).resolve().parent.parent / "data" / "vtest.avi"


CPU: dict[str, float] = {}  # frames per second of this process's CPU time, by row


def _rate(run: Callable[[int], object], frames: int, repeats: int, row: str) -> float:
    """Median wall-clock frames/s; also records frames per CPU-second (less load-sensitive)."""
    rates, cpu_rates = [], []
    for _ in range(repeats):
        start, cpu = time.perf_counter(), time.process_time()
        for i in range(frames):
            run(i)
        rates.append(frames / (time.perf_counter() - start))
        cpu_rates.append(frames / max(time.process_time() - cpu, 1e-9))
    CPU[row] = statistics.median(cpu_rates)
    return statistics.median(rates)


def _capture_rate(path: Path, frames: int, repeats: int) -> float:
    rates = []
    for _ in range(repeats):
        capture = cv2.VideoCapture(str(path))
        start = time.perf_counter()
        for _ in range(frames):
            capture.read()
        rates.append(frames / (time.perf_counter() - start))
        capture.release()
    return statistics.median(rates)


def _source_rate(path: Path, frames: int, repeats: int) -> float:
    rates = []
    for _ in range(repeats):
        source = VideoFileSource(str(path)).open()
        start = time.perf_counter()
        for i in range(frames):
            source.read(i)
        rates.append(frames / (time.perf_counter() - start))
        source.close()
    return statistics.median(rates)


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--frames", type=int, default=200)
    parser.add_argument("--repeats", type=int, default=3)
    args = parser.parse_args()
    cv2.setNumThreads(1)
    n, r = args.frames, args.repeats
    rows: dict[str, float] = {}

    visible = SceneSource(0, params=SceneParams(frame_count=n))
    visible.read(0)  # background, noise bank and plan are built once, before timing
    rows["synthetic"] = _rate(visible.read, n, r, "synthetic")
    thermal = SceneSource(0, thermal=True, params=SceneParams(frame_count=n))
    thermal.read(0)
    rows["synthetic-thermal"] = _rate(thermal.read, n, r, "synthetic-thermal")
    scene = Scene(0, SceneParams(frame_count=n))
    scene.frame_truth(0)
    rows["synthetic-gt"] = _rate(scene.frame_truth, n, r, "synthetic-gt")

    with tempfile.TemporaryDirectory() as tmp:
        video, _ = write_scene(tmp, 0, n)
        rows["video-source (scene.avi)"] = _source_rate(video, n, r)
        rows["videocapture (scene.avi)"] = _capture_rate(video, n, r)
    if VTEST.is_file():
        rows["vtest-source"] = _source_rate(VTEST, min(n, 795), r)
        rows["vtest-videocapture"] = _capture_rate(VTEST, min(n, 795), r)

    print(f"{'row':32s} {'frames/s':>10s} {'per CPU-s':>10s}")
    for name, rate in rows.items():
        cpu = f"{CPU[name]:10.1f}" if name in CPU else f"{'-':>10s}"
        print(f"{name:32s} {rate:10.1f} {cpu}")
    RESULTS.parent.mkdir(parents=True, exist_ok=True)
    RESULTS.write_text(
        json.dumps(
            {
                "frames": n,
                "repeats": r,
                "opencv_threads": 1,
                "machine": platform.platform(),
                "frames_per_second": rows,
                "frames_per_cpu_second": CPU,
                "note": "median of repeats; shared 2-core machine, noisy",
            },
            indent=2,
        )
        + "\n"
    )
    print(f"wrote {RESULTS}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
