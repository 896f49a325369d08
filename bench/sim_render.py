"""Render rate of the simulated dome's view on one core, against naive peers in the same run.

    .venv/bin/python -m bench.sim_render [--frames N] [--repeats R]

For each wide size (768x576, 1920x1080) it renders 640x480 views along a moving pose (a new
pose every frame: the worst case, nothing cached) with:
- `ptzd`: `CameraModel.render` (one cv2.warpPerspective on a BGRA copy made once per wide frame),
- `ptzd+prepare`: the same, converting the wide frame every render (a new wide frame per view),
- `warp-bgr`: one plain 3-channel cv2.warpPerspective,
- `remap-naive`: per-frame numpy map computation + cv2.remap (the straightforward peer).
Prints a table of median frames/s over R repeats and writes bench/results/sim_render.json.
The machine is shared by several people: numbers are noisy; compare rows of one run.
"""

from __future__ import annotations

import argparse
import json
import platform
import statistics
import time
from collections.abc import Callable
from pathlib import Path

import cv2
import numpy as np

from ptzd.sim.camera_model import CameraModel, Pose

VIEW = (640, 480)
WIDE_SIZES = [(768, 576), (1920, 1080)]
RESULTS = Path(__file__).resolve().parent / "results" / "sim_render.json"


def _poses(n: int) -> list[Pose]:
    return [
        Pose(-20.0 + 40.0 * i / n, 10.0 * np.sin(i / 7.0), 10.0 + 40.0 * i / n) for i in range(n)
    ]


def _remap_naive(model: CameraModel, wide: np.ndarray, pose: Pose) -> np.ndarray:
    H = model.geometry(pose).view_to_wide
    u, v = np.meshgrid(np.arange(VIEW[0], dtype=np.float64), np.arange(VIEW[1], dtype=np.float64))
    x = H[0, 0] * u + H[0, 1] * v + H[0, 2]
    y = H[1, 0] * u + H[1, 1] * v + H[1, 2]
    z = H[2, 0] * u + H[2, 1] * v + H[2, 2]
    with np.errstate(divide="ignore", invalid="ignore"):
        map_x = np.where(z > 0, x / z, -1.0).astype(np.float32)
        map_y = np.where(z > 0, y / z, -1.0).astype(np.float32)
    return cv2.remap(wide, map_x, map_y, cv2.INTER_LINEAR, borderMode=cv2.BORDER_CONSTANT)


def _methods(
    model: CameraModel, fresh: CameraModel, wide: np.ndarray
) -> dict[str, Callable[[Pose], object]]:
    """The renderers compared: ours (prepared once / per frame) and the naive peers."""
    prepared = model.prepare(wide)

    def ptzd(pose: Pose) -> object:
        return model.render(prepared, pose)

    def ptzd_prepare(pose: Pose) -> object:
        return model.render(wide, pose)

    def warp_bgr(pose: Pose) -> object:
        H = fresh.geometry(pose).view_to_wide
        return cv2.warpPerspective(wide, H, VIEW, flags=cv2.INTER_LINEAR | cv2.WARP_INVERSE_MAP)

    def remap_naive(pose: Pose) -> object:
        return _remap_naive(fresh, wide, pose)

    return {
        "ptzd": ptzd,
        "ptzd+prepare": ptzd_prepare,
        "warp-bgr": warp_bgr,
        "remap-naive": remap_naive,
    }


def _rate(render: Callable[[Pose], object], poses: list[Pose]) -> float:
    for pose in poses[:10]:  # warm-up
        render(pose)
    start = time.perf_counter()
    for pose in poses:
        render(pose)
    return len(poses) / (time.perf_counter() - start)


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--frames", type=int, default=400)
    parser.add_argument("--repeats", type=int, default=5)
    args = parser.parse_args()
    cv2.setNumThreads(1)  # one core, as on the 2-core target with the daemon on the other
    rng = np.random.default_rng(0)
    rows: list[dict[str, object]] = []
    for wide_size in WIDE_SIZES:
        small = rng.integers(0, 256, (wide_size[1] // 8, wide_size[0] // 8, 3), dtype=np.uint8)
        wide = np.asarray(
            cv2.resize(small, wide_size, interpolation=cv2.INTER_LINEAR), dtype=np.uint8
        )
        model = CameraModel(wide_size, 90.0, VIEW)
        poses = _poses(args.frames)
        fresh = CameraModel(wide_size, 90.0, VIEW)
        methods = _methods(model, fresh, wide)
        for name, render in methods.items():
            rates = [_rate(render, poses) for _ in range(args.repeats)]
            rows.append(
                {
                    "wide": f"{wide_size[0]}x{wide_size[1]}",
                    "view": f"{VIEW[0]}x{VIEW[1]}",
                    "method": name,
                    "fps_median": statistics.median(rates),
                    "fps_min": min(rates),
                    "fps_max": max(rates),
                    "repeats": args.repeats,
                    "frames": args.frames,
                }
            )
    print(f"{'wide':>10} {'method':>13} {'fps median':>11} {'min':>8} {'max':>8}")
    for row in rows:
        print(
            f"{row['wide']:>10} {row['method']:>13} {row['fps_median']:>11.0f} "
            f"{row['fps_min']:>8.0f} {row['fps_max']:>8.0f}"
        )
    RESULTS.parent.mkdir(parents=True, exist_ok=True)
    meta = {"python": platform.python_version(), "opencv": cv2.__version__, "threads": 1}
    RESULTS.write_text(json.dumps({"meta": meta, "rows": rows}, indent=2) + "\n")
    print(f"wrote {RESULTS}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
