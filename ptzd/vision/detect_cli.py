"""Command-line entry points of person detection: `ptzd detect`, `ptzd codebook`.

`ptzd detect VIDEO --out dets.json [--overlay OUT.mp4] [--detector bgcode|hog]` runs the
detector over every frame of a video (or `synthetic[:SEED]`) with a still camera and writes
`{"frames": {"<frame>": [[x, y, w, h, score], ...]}}` (every frame, empty lists included).

`ptzd codebook train --source synthetic:1 ... [--labelled VIDEO GT.json] --out CB.npz`
builds a codebook from the silhouettes the detector's own background model cuts out of
labelled sequences; `ptzd codebook show [CB.npz]` prints one (default: the shipped one).
"""

from __future__ import annotations

import argparse
import json
import shlex
import sys
import time
from pathlib import Path
from typing import Any

from ptzd.errors import UsageError

DETECTORS = ("bgcode", "hog")


def register(subparsers: argparse._SubParsersAction[Any]) -> None:
    """Add `detect` and `codebook`."""
    detect = subparsers.add_parser(
        "detect", help="detect people in a video offline and write their boxes as JSON"
    )
    detect.add_argument("video", metavar="VIDEO", help="video file, or synthetic[:SEED]")
    detect.add_argument("--out", required=True, metavar="dets.json", help="where to write boxes")
    detect.add_argument("--overlay", metavar="OUT.mp4", help="also write a video with the boxes")
    detect.add_argument("--detector", choices=DETECTORS, default=None, help="default: config's")
    detect.add_argument("--codebook", metavar="CB.npz", help="codebook (default: config's)")
    detect.add_argument("--config", metavar="PTZD.toml", help="take [detector] from this file")
    detect.add_argument("--max-frames", type=int, default=None, metavar="N", help="stop after N")
    detect.set_defaults(handler=_detect)

    codebook = subparsers.add_parser("codebook", help="train or inspect detection codebooks")
    sub = codebook.add_subparsers(dest="codebook_command", metavar="ACTION")
    sub.required = True
    train = sub.add_parser("train", help="build a codebook from labelled sequences")
    train.add_argument(
        "--source",
        action="append",
        default=[],
        metavar="SPEC",
        help="synthetic[:SEED] (simulator scene) or figures:SEED (procedural); repeatable",
    )
    train.add_argument(
        "--labelled",
        action="append",
        nargs=2,
        default=[],
        metavar=("VIDEO", "GT.json"),
        help="a video and its ground-truth file; repeatable",
    )
    train.add_argument("--out", required=True, metavar="CB.npz", help="codebook file to write")
    train.add_argument("--size", type=int, default=32, help="number of code words (default 32)")
    train.add_argument("--seed", type=int, default=0, help="LBG seed (default 0)")
    train.add_argument("--stride", type=int, default=1, help="use every Nth frame (default 1)")
    train.add_argument(
        "--min-height", type=int, default=36, help="shortest silhouette used, px (default 36)"
    )
    train.add_argument(
        "--max-frames", type=int, default=None, metavar="N", help="frames per source (default all)"
    )
    train.add_argument(
        "--quantile", type=float, default=0.99, help="training-distortion quantile (0.99)"
    )
    train.add_argument("--margin", type=float, default=1.15, help="threshold = quantile*margin")
    train.add_argument(
        "--scene-size", metavar="WxH", default=None, help="render synthetic scenes at this size"
    )
    train.add_argument("--config", metavar="PTZD.toml", help="take [detector.bgcode] from here")
    train.set_defaults(handler=_train)
    show = sub.add_parser("show", help="print a codebook's summary as JSON")
    show.add_argument("path", nargs="?", default=None, help="default: the shipped codebook")
    show.set_defaults(handler=_show)


def _detector_config(path: str | None) -> Any:
    from ptzd.config import load_config
    from ptzd.vision.detect.config import DetectorConfig

    return load_config(path).detector if path else DetectorConfig()


def _detect(args: argparse.Namespace) -> int:
    import cv2

    from ptzd.sim.sources import open_wide_source
    from ptzd.vision.detect.factory import build_detector

    config = _detector_config(args.config)
    updates: dict[str, Any] = {}
    if args.detector:
        updates["kind"] = args.detector
        updates["when_moving"] = "wait"
    if args.codebook:
        updates["bgcode"] = config.bgcode.model_copy(update={"codebook": args.codebook})
    config = config.model_copy(update=updates)
    detector = build_detector(config)
    source = open_wide_source(args.video)
    count = source.frame_count
    if args.max_frames is not None:
        count = args.max_frames if count is None else min(count, args.max_frames)
    if count is None:
        raise UsageError(f"{args.video} is endless: give --max-frames")
    writer: Any = None
    if args.overlay:
        writer = cv2.VideoWriter(
            args.overlay, cv2.VideoWriter.fourcc(*"mp4v"), source.fps, source.size
        )
        if not writer.isOpened():
            raise UsageError(f"cannot write {args.overlay}")
    frames: dict[str, list[list[float]]] = {}
    spent = 0.0
    try:
        for i in range(count):
            frame = source.read(i)
            start = time.perf_counter()
            found = detector.detect(frame)
            spent += time.perf_counter() - start
            frames[str(i)] = [d.to_list() for d in found]
            if writer is not None:
                for d in found:
                    p0 = (round(d.x), round(d.y))
                    p1 = (round(d.x + d.w), round(d.y + d.h))
                    cv2.rectangle(frame, p0, p1, (0, 255, 0), 2)
                    cv2.putText(
                        frame,
                        f"{d.score:.2f}",
                        (p0[0], max(10, p0[1] - 3)),
                        cv2.FONT_HERSHEY_SIMPLEX,
                        0.4,
                        (0, 255, 0),
                        1,
                    )
                writer.write(frame)
    finally:
        if writer is not None:
            writer.release()
    Path(args.out).write_text(json.dumps({"frames": frames}) + "\n", encoding="utf-8")
    total = sum(len(v) for v in frames.values())
    ms = 1000.0 * spent / max(1, count)
    print(
        f"{detector.name}: {count} frames, {total} detections, {ms:.2f} ms/frame", file=sys.stderr
    )
    return 0


def _train(args: argparse.Namespace) -> int:
    import numpy as np

    from ptzd.vision.detect.codebook import train_codebook
    from ptzd.vision.detect.training import (
        TrainingSourceError,
        open_training_source,
        sequence_profiles,
    )

    if not args.source and not args.labelled:
        raise UsageError("give at least one --source or --labelled sequence")
    if args.size < 1 or args.stride < 1:
        raise UsageError("--size and --stride must be >= 1")
    if not 0.5 <= args.quantile <= 1.0 or args.margin < 1.0:
        raise UsageError("--quantile must be in [0.5, 1] and --margin >= 1")
    bgcode = _detector_config(args.config).bgcode
    scene_size = _parse_size(args.scene_size) if args.scene_size else None
    specs: list[tuple[str, str | None]] = [(s, None) for s in args.source]
    specs += [(v, g) for v, g in args.labelled]
    profiles = []
    per_source: dict[str, int] = {}
    for spec, gt in specs:
        try:
            seq = open_training_source(spec, gt=gt, scene_size=scene_size)
        except TrainingSourceError as exc:
            raise UsageError(str(exc)) from None
        found = sequence_profiles(
            seq, bgcode, stride=args.stride, max_frames=args.max_frames, min_height=args.min_height
        )
        per_source[spec] = int(found.shape[0])
        print(f"{spec}: {found.shape[0]} silhouettes", file=sys.stderr)
        profiles.append(found)
    stacked = np.concatenate(profiles) if profiles else np.zeros((0, 90), np.float32)
    if stacked.shape[0] < max(2, args.size):
        raise UsageError(
            f"only {stacked.shape[0]} silhouettes found; need at least {max(2, args.size)}"
        )
    provenance = json.dumps(
        {
            "command": _train_command(args),
            "silhouettes": per_source,
            "size": args.size,
            "seed": args.seed,
            "quantile": args.quantile,
            "margin": args.margin,
            "bgcode": bgcode.model_dump(mode="json"),
        }
    )
    book = train_codebook(
        stacked,
        size=args.size,
        seed=args.seed,
        quantile=args.quantile,
        margin=args.margin,
        provenance=provenance,
    )
    book.save(args.out)
    print(json.dumps(book.summary(), indent=2))
    return 0


def _parse_size(text: str) -> tuple[int, int]:
    try:
        w, h = (int(v) for v in text.lower().split("x"))
    except ValueError:
        raise UsageError(f"--scene-size must be WxH, got {text!r}") from None
    if w < 1 or h < 1:
        raise UsageError(f"--scene-size must be positive, got {text!r}")
    return w, h


def _train_command(args: argparse.Namespace) -> str:
    """The command line that regenerates this codebook (recorded as its provenance)."""
    parts = ["ptzd", "codebook", "train"]
    for spec in args.source:
        parts += ["--source", spec]
    for video, gt in args.labelled:
        parts += ["--labelled", video, gt]
    parts += ["--size", str(args.size), "--seed", str(args.seed), "--stride", str(args.stride)]
    if args.min_height != 36:
        parts += ["--min-height", str(args.min_height)]
    if args.max_frames is not None:
        parts += ["--max-frames", str(args.max_frames)]
    if args.scene_size:
        parts += ["--scene-size", args.scene_size]
    parts += ["--quantile", str(args.quantile), "--margin", str(args.margin)]
    if args.config:
        parts += ["--config", args.config]
    parts += ["--out", args.out]
    return " ".join(shlex.quote(p) for p in parts)


def _show(args: argparse.Namespace) -> int:
    from ptzd.vision.detect.codebook import Codebook, CodebookError

    try:
        book = Codebook.load(args.path) if args.path else Codebook.load_default()
    except CodebookError as exc:
        raise UsageError(str(exc)) from None
    print(json.dumps(book.summary(), indent=2))
    return 0
