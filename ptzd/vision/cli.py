"""Command-line entry points of `ptzd.vision`: `ptzd track`.

`ptzd track VIDEO --init X,Y,W,H [--start N] [--end M] --out OUT.json` tracks the target
whose box is given in frame N through frames N..M inclusive (frame 0 is the first frame
cv2.VideoCapture reads). OUT.json holds every frame N..M: the init frame with the init box
(clipped to the frame) and then the tracker's box, or null while it has lost the target.
`fps` counts tracked frames per second of tracker time, excluding decoding and init.
"""

from __future__ import annotations

import argparse
import itertools
import json
import sys
import time
from collections.abc import Generator
from pathlib import Path
from typing import TYPE_CHECKING, Any

from ptzd.errors import UsageError

if TYPE_CHECKING:
    import numpy as np
    from numpy.typing import NDArray

    from ptzd.vision.config import TrackerConfig

TRACKERS = ("color", "rf", "svm", "auto")


def register(subparsers: argparse._SubParsersAction[Any]) -> None:
    """Add `track`."""
    track = subparsers.add_parser(
        "track", help="track one target through a video offline and write its boxes as JSON"
    )
    track.add_argument(
        "video", metavar="VIDEO", help="video file cv2 can read, or synthetic[:SEED] (simulator)"
    )
    track.add_argument(
        "--init", required=True, metavar="X,Y,W,H", help="target box in frame --start, pixels"
    )
    track.add_argument("--start", type=int, default=0, metavar="N", help="first frame (default 0)")
    track.add_argument(
        "--end", type=int, default=None, metavar="M", help="last frame, inclusive (default: last)"
    )
    track.add_argument(
        "--tracker",
        choices=TRACKERS,
        default=None,
        help=(
            "tracker: color (seed 002), rf (seed 000, grey/thermal), svm (seed 004), auto"
            " (color on colour frames, rf on grey ones: a day/night camera; [tracker.auto]);"
            " default: the config's [tracker] kind, auto"
        ),
    )
    track.add_argument("--out", required=True, metavar="OUT.json", help="where to write boxes")
    track.add_argument("--overlay", metavar="OUT.mp4", help="also write a video with the boxes")
    track.add_argument("--seed", type=int, default=None, help="random seed (default: config's)")
    track.add_argument(
        "--particles", type=int, default=None, metavar="N", help="number of particles"
    )
    track.add_argument("--config", metavar="PTZD.toml", help="take [tracker] from this config file")
    track.set_defaults(handler=_track)


def parse_box(text: str) -> tuple[float, float, float, float]:
    """`X,Y,W,H` -> floats; UsageError when malformed or not of positive size."""
    parts = text.split(",")
    try:
        values = [float(p) for p in parts]
    except ValueError:
        raise UsageError(f"--init must be X,Y,W,H numbers, got {text!r}") from None
    if len(values) != 4:
        raise UsageError(f"--init must be four numbers X,Y,W,H, got {text!r}")
    x, y, w, h = values
    if not all(v == v and abs(v) != float("inf") for v in values):
        raise UsageError(f"--init must be finite numbers, got {text!r}")
    if w <= 0 or h <= 0:
        raise UsageError(f"--init box must have positive width and height, got {text!r}")
    return x, y, w, h


def clip_box(
    box: tuple[float, float, float, float], width: int, height: int
) -> tuple[float, float, float, float]:
    """The part of `box` inside a width x height frame; UsageError when (nearly) none is."""
    x, y, w, h = box
    x0, y0 = max(x, 0.0), max(y, 0.0)
    x1, y1 = min(x + w, float(width)), min(y + h, float(height))
    if x1 - x0 < 2 or y1 - y0 < 2:
        raise UsageError(
            f"--init box {x:g},{y:g},{w:g},{h:g} lies outside the {width}x{height} frame"
        )
    return x0, y0, x1 - x0, y1 - y0


def _tracker_config(args: argparse.Namespace) -> TrackerConfig:
    from ptzd.vision.config import TrackerConfig

    config = TrackerConfig()
    if args.config:
        from ptzd.config import load_config

        config = load_config(args.config).tracker
    changes: dict[str, Any] = {} if args.tracker is None else {"kind": args.tracker}
    if args.seed is not None:
        changes["seed"] = args.seed
    if args.particles is not None:
        changes["num_particles"] = args.particles
    data = config.model_dump()
    kind = changes.get("kind", config.kind)
    if args.particles is not None and kind in ("rf", "svm"):
        # rf and svm keep their own particle counts in their sub-tables (auto: color's here)
        changes.pop("num_particles")
        data[kind] = {**data[kind], "num_particles": args.particles}
    try:
        return TrackerConfig.model_validate({**data, **changes})
    except ValueError as exc:
        first = str(exc).splitlines()
        raise UsageError(f"bad tracker option: {' '.join(first[:3])}") from None


class _Progress:
    """A one-line progress bar on stderr, only when stderr is a terminal."""

    def __init__(self, total: int) -> None:
        self._total = max(total, 1)
        self._enabled = sys.stderr.isatty()
        self._last = -1

    def show(self, done: int) -> None:
        if not self._enabled:
            return
        percent = 100 * done // self._total
        if percent == self._last:
            return
        self._last = percent
        bar = "#" * (percent // 4)
        sys.stderr.write(f"\rtracking [{bar:<25}] {percent:3d}% ({done}/{self._total})")
        sys.stderr.flush()

    def close(self) -> None:
        if self._enabled:
            sys.stderr.write("\n")


def _track(args: argparse.Namespace) -> int:

    from ptzd.vision.tracking import TrackState, make_tracker

    init_box = parse_box(args.init)
    if args.start < 0:
        raise UsageError(f"--start must be >= 0, got {args.start}")
    if args.end is not None and args.end < args.start:
        raise UsageError(f"--end {args.end} is before --start {args.start}")
    config = _tracker_config(args)
    frames, video_fps, frame_count = _open_frames(args.video)
    try:
        frame = next(frames, None)
        if frame is None:
            raise UsageError(f"cannot read video {args.video}: not a video cv2 can decode")
        for index in range(1, args.start + 1):
            frame = next(frames, None)
            if frame is None:
                raise UsageError(
                    f"--start {args.start} is beyond the end of {args.video} ({index} frames)"
                )
        height, width = frame.shape[:2]
        box = clip_box(init_box, width, height)
        tracker = make_tracker(config)
        tracker.init(frame, box)
        boxes: dict[str, list[float] | None] = {str(args.start): [round(v, 2) for v in box]}
        writer = _overlay_writer(args.overlay, video_fps, width, height)
        if writer is not None:
            writer.write(_draw(frame, box, TrackState.TRACKING, args.start))
        total = args.end if args.end is not None else (frame_count or args.start + 1) - 1
        progress = _Progress(total - args.start)
        tracked, elapsed, cpu = 0, 0.0, 0.0
        index = args.start
        while args.end is None or index < args.end:
            frame = next(frames, None)
            if frame is None:
                break
            index += 1
            t0, c0 = time.perf_counter(), time.process_time()
            result = tracker.update(frame)
            elapsed += time.perf_counter() - t0
            cpu += time.process_time() - c0
            tracked += 1
            lost = result.state is TrackState.LOST
            boxes[str(index)] = None if lost else [round(v, 2) for v in result.box]
            if writer is not None:
                writer.write(_draw(frame, result.box, result.state, index))
            progress.show(tracked)
        progress.close()
        if writer is not None:
            writer.release()
    finally:
        frames.close()
    fps = tracked / elapsed if elapsed > 0 else 0.0
    params: dict[str, Any] = {
        "tracker": config.kind,
        "init": list(init_box),
        "start": args.start,
        "end": index,
        # frames per second of this process's CPU time in update(): what one free core
        # would do, unlike `fps`, which a busy machine drags down
        "cpu_fps": round(tracked / cpu, 1) if cpu > 0 else 0.0,
        "config": config.model_dump(mode="json"),
    }
    out = {"boxes": boxes, "fps": round(fps, 1), "params": params}
    Path(args.out).write_text(json.dumps(out, indent=1) + "\n")
    return 0


def _open_frames(video: str) -> tuple[Generator[NDArray[np.uint8]], float, int | None]:
    """Frames 0, 1, ... of a video file or of `synthetic[:SEED]`, its fps and frame count."""
    if video.split(":", 1)[0] in ("synthetic", "synthetic-thermal"):
        from ptzd.sim.sources import open_wide_source

        source = open_wide_source(video)
        count = source.frame_count
        indices = range(count) if count is not None else itertools.count()
        return (source.read(i) for i in indices), source.fps, count
    import cv2

    if not Path(video).is_file():
        raise UsageError(f"cannot read video {video}: no such file")
    capture = cv2.VideoCapture(video)
    fps = float(capture.get(cv2.CAP_PROP_FPS)) or 10.0
    count = int(capture.get(cv2.CAP_PROP_FRAME_COUNT)) or None
    return _decode(capture), fps, count


def _decode(capture: Any) -> Generator[NDArray[np.uint8]]:
    """8-bit BGR frames until the end (or a decode error); releases the capture when closed."""
    import numpy as np

    try:
        while capture.isOpened():
            ok, frame = capture.read()
            if not ok or frame is None:
                return
            yield np.asarray(frame, dtype=np.uint8)
    finally:
        capture.release()


def _overlay_writer(path: str | None, fps: float, width: int, height: int) -> Any:
    if path is None:
        return None
    import cv2

    writer = cv2.VideoWriter(path, cv2.VideoWriter.fourcc(*"mp4v"), fps, (width, height))
    if not writer.isOpened():
        raise UsageError(f"cannot write overlay video {path}")
    return writer


_STATE_COLOURS = {"tracking": (0, 220, 0), "occluded": (0, 200, 255), "lost": (0, 0, 255)}


def _draw(
    frame: NDArray[np.uint8], box: tuple[float, float, float, float], state: str, index: int
) -> NDArray[np.uint8]:
    import cv2

    out = frame.copy()
    x, y, w, h = (round(v) for v in box)
    colour = _STATE_COLOURS[str(state)]
    cv2.rectangle(out, (x, y), (x + w, y + h), colour, 2)
    cv2.putText(out, f"{index} {state}", (8, 20), cv2.FONT_HERSHEY_SIMPLEX, 0.6, colour, 2)
    return out
