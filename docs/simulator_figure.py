"""Draw docs/simulator.jpg with the simulator itself: a wide frame of the synthetic scene with
the footprints of two dome poses, and the views the simulator renders at those poses.

    .venv/bin/python docs/simulator_figure.py
"""

from __future__ import annotations

from pathlib import Path

import cv2
import numpy as np

from ptzd.sim.camera_model import CameraModel, Pose
from ptzd.sim.sources import open_wide_source

OUT = Path(__file__).resolve().parent / "simulator.jpg"
POSES = [(Pose(-12.0, -6.0, 30.0), (0, 200, 255)), (Pose(20.0, 2.0, 10.0), (255, 160, 0))]
VIEW = (320, 240)


def main() -> None:
    source = open_wide_source("synthetic:0")
    wide = source.read(120)
    model = CameraModel(source.size, 90.0, VIEW)
    canvas = wide.copy()
    views = []
    w, h = VIEW
    border = np.concatenate(
        [
            np.c_[np.linspace(0, w, 50), np.zeros(50)],
            np.c_[np.full(50, w), np.linspace(0, h, 50)],
            np.c_[np.linspace(w, 0, 50), np.full(50, h)],
            np.c_[np.zeros(50), np.linspace(h, 0, 50)],
        ]
    )
    for pose, colour in POSES:
        outline = model.view_to_wide(border, pose)
        cv2.polylines(canvas, [np.round(outline).astype(np.int32)], True, colour, 3, cv2.LINE_AA)
        view = model.render(wide, pose)
        cv2.rectangle(view, (0, 0), (w - 1, h - 1), colour, 4)
        text = f"pan {pose.pan:+.0f} tilt {pose.tilt:+.0f} hfov {pose.hfov:.0f}"
        for ink, thickness in (((0, 0, 0), 3), (colour, 1)):  # outlined, readable on any ground
            cv2.putText(view, text, (8, h - 10), 0, 0.5, ink, thickness, cv2.LINE_AA)
        views.append(view)
    scale = 2 * h / canvas.shape[0]
    left = cv2.resize(canvas, None, fx=scale, fy=scale, interpolation=cv2.INTER_AREA)
    cv2.putText(left, "wide frame, hfov 90", (8, 20), 0, 0.6, (255, 255, 255), 1, cv2.LINE_AA)
    figure = np.hstack([left, np.vstack(views)])
    cv2.imwrite(str(OUT), figure, [cv2.IMWRITE_JPEG_QUALITY, 80])
    print(f"wrote {OUT} ({OUT.stat().st_size // 1024} KiB)")


if __name__ == "__main__":
    main()
