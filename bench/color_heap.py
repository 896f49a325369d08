"""Heap and time of the colour likelihood, hard value bins against soft ones.

The daemon runs for months: what the colour likelihood keeps between frames, and how much
the heap swings while it works, matter as much as its speed. This replays the colour
tracker's likelihood work on vtest frames: every frame the particles' histograms (N boxes
round the pedestrian), and every fifth one a frame-wide scan as while LOST (350-600
boxes, their size changing from scan to scan, as the scan's count does with the box
size). Each configuration runs in a fresh process pinned to one core; glibc's own
counters (`mallinfo2`) give the heap in use.

    .venv/bin/python -m bench.color_heap [--frames 600] [--particles 300]
        [--out bench/results/color_heap.json]

Prints a table (median ms per frame, heap in use at its peak and at the end, anonymous
RSS at the end) and writes JSON. Needs data/vtest.avi (scripts/fetch-vtest.sh).
"""

from __future__ import annotations

import os

# Before numpy loads (in `measure`): one BLAS/OpenMP thread, so one core means one core.
os.environ.setdefault("OMP_NUM_THREADS", "1")
os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")

import argparse
import ctypes
import json
import statistics
import subprocess
import sys
import time
from pathlib import Path
from typing import Any

ROOT = Path(__file__).resolve().parent.parent
VIDEO = ROOT / "data" / "vtest.avi"
CONFIGS = {"hard bins (value_blend 0)": 0.0, "soft bins (value_blend 0.5)": 0.5}
BOX = (585.0, 241.0, 38.0, 85.0)  # a pedestrian of vtest's first frame, centre form


class _MallInfo2(ctypes.Structure):
    _fields_ = [
        (name, ctypes.c_size_t)
        for name in (
            "arena", "ordblks", "smblks", "hblks", "hblkhd", "usmblks", "fsmblks", "uordblks",
            "fordblks", "keepcost",
        )
    ]  # fmt: skip


def heap_in_use_mb() -> float:
    """Bytes malloc has handed out and not had back (heap and mmapped chunks), in MB."""
    libc = ctypes.CDLL("libc.so.6")
    libc.mallinfo2.restype = _MallInfo2
    info = libc.mallinfo2()
    return float(info.uordblks + info.hblkhd) / 2**20


def rss_anon_mb() -> float:
    with open("/proc/self/status") as status:
        for line in status:
            if line.startswith("RssAnon:"):
                return int(line.split()[1]) / 1024
    return float("nan")


def measure(value_blend: float, frames: int, particles: int) -> dict[str, Any]:
    """One configuration, in this process."""
    import cv2
    import numpy as np

    from ptzd.sim.sources import open_wide_source
    from ptzd.vision.color import ColorLikelihood
    from ptzd.vision.config import ColorConfig, GmmConfig

    cv2.setNumThreads(1)
    if not VIDEO.is_file():
        raise SystemExit(f"no {VIDEO}: run scripts/fetch-vtest.sh")
    video = open_wide_source(str(VIDEO))
    images = [video.read(i) for i in range(50)]
    likelihood = ColorLikelihood(ColorConfig(value_blend=value_blend), GmmConfig())
    likelihood.init(images[0], np.array(BOX))
    rng = np.random.default_rng(0)
    height, width = images[0].shape[:2]
    times, peak = [], 0.0
    for i in range(frames):
        image = images[i % len(images)]
        boxes = np.column_stack(
            [
                rng.normal(BOX[0], 10.0, particles),
                rng.normal(BOX[1], 10.0, particles),
                np.full(particles, BOX[2]),
                np.full(particles, BOX[3]),
            ]
        )
        started = time.perf_counter()
        likelihood.log_likelihood(image, boxes)
        times.append(time.perf_counter() - started)
        if i % 5 == 0:
            n = int(rng.integers(350, 601))
            w = float(rng.uniform(20.0, 60.0))
            scan = np.column_stack(
                [
                    rng.uniform(0, width, n),
                    rng.uniform(0, height, n),
                    np.full(n, w),
                    np.full(n, 2.2 * w),
                ]
            )
            likelihood.log_likelihood(image, scan)
        peak = max(peak, heap_in_use_mb())
    return {
        "value_blend": value_blend,
        "particles": particles,
        "frames": frames,
        "ms_per_frame_median": round(1000 * statistics.median(times[20:]), 3),
        "heap_in_use_peak_mb": round(peak, 1),
        "heap_in_use_end_mb": round(heap_in_use_mb(), 1),
        "rss_anon_end_mb": round(rss_anon_mb(), 1),
    }


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--frames", type=int, default=600)
    parser.add_argument("--particles", type=int, default=300)
    parser.add_argument("--out", type=Path, default=ROOT / "bench" / "results" / "color_heap.json")
    parser.add_argument("--one", type=float, help=argparse.SUPPRESS)  # a child's value_blend
    args = parser.parse_args(argv)
    if args.one is not None:
        print(json.dumps(measure(args.one, args.frames, args.particles)))
        return 0
    rows = {}
    for label, blend in CONFIGS.items():
        child = subprocess.run(
            ["taskset", "-c", "0", sys.executable, "-m", "bench.color_heap", "--one", str(blend),
             "--frames", str(args.frames), "--particles", str(args.particles)],
            cwd=ROOT, capture_output=True, text=True, check=True,
        )  # fmt: skip
        rows[label] = json.loads(child.stdout.strip().splitlines()[-1])
    header = ("configuration", "ms/frame", "heap peak", "heap end", "RSS anon")
    print(f"{header[0]:30s} {header[1]:>9s} {header[2]:>10s} {header[3]:>9s} {header[4]:>9s}")
    for label, row in rows.items():
        print(
            f"{label:30s} {row['ms_per_frame_median']:9.2f} {row['heap_in_use_peak_mb']:8.1f}MB"
            f" {row['heap_in_use_end_mb']:7.1f}MB {row['rss_anon_end_mb']:7.1f}MB"
        )
    args.out.parent.mkdir(parents=True, exist_ok=True)
    args.out.write_text(json.dumps({"argv": sys.argv[1:], "rows": rows}, indent=1) + "\n")
    print(f"wrote {args.out}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
