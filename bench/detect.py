"""Detection benchmark: recall / precision at IoU >= 0.5 and ms per 640x480 frame.

Runs the seed-002 background + codebook detector (`bgcode`) on the simulator's synthetic
scenes rendered at 640x480 with a still camera, and OpenCV's HOG people detector as the
peer in the same run. Frames are rendered before timing, so ms/frame is detection only
(grey conversion, background update, regions, features, matching), on one core
(cv2.setNumThreads(1)). Scenes 1-3 are held out from the shipped codebook's training
(scenes 11-16).

Scoring (ptzd.vision.detect.evaluate): people fully in view, >= 90 % visible and touching no
one else count; partly hidden or merged people are don't-care. Reported twice: people at
least `--min-height` px tall (default 36; the detector's own `min_height` is 30) and all
sizes. The
first `skip` frames (background warm-up) are not scored. The detector config is the
defaults plus `PTZD_DETECTOR__...` environment overrides. HOG (stateless, ~100x slower) is
scored on every `--hog-stride`th frame and upscaled by `--hog-resize`: its window is 64x128
and most people in a 640x480 scene are 36-120 px tall.

HOG is not in OpenCV 5's Python wheels; when this interpreter lacks it, the peer runs in
the bench venv (`.venv-bench`, or `--peer-python`) if that has it, else is reported as
unavailable.

    .venv/bin/python -m bench.detect [--seeds 1,2,3] [--frames 300] [--json PATH]
"""

from __future__ import annotations

import argparse
import json
import os
import statistics
import subprocess
import sys
import time
from pathlib import Path
from typing import Any

import cv2
import numpy as np

REPO = Path(__file__).resolve().parents[1]


def _score(
    kind: str,
    seeds: list[int],
    frames: int,
    skip: int,
    min_height: int,
    *,
    stride: int = 1,
    hog_resize: float = 2.0,
) -> dict[str, Any]:
    from ptzd.config import validate_config
    from ptzd.sim.scene import SceneParams, SceneSource
    from ptzd.vision.detect.evaluate import DetectionScore
    from ptzd.vision.detect.factory import make_detector

    # defaults plus PTZD_DETECTOR__... environment overrides, like the daemon
    config = validate_config({}).detector
    config = config.model_copy(
        update={
            "kind": kind,
            "when_moving": "wait",
            "hog": config.hog.model_copy(update={"resize": hog_resize}),
        }
    )

    cv2.setNumThreads(1)
    tall, every = DetectionScore(), DetectionScore()
    times: list[float] = []
    per_seed = {}
    for seed in seeds:
        source = SceneSource(seed, params=SceneParams(width=640, height=480, frame_count=frames))
        truth = source.ground_truth
        images = [source.read(i) for i in range(frames)]
        detector = make_detector(config)
        seed_score = DetectionScore()
        for i, image in enumerate(images):
            if i % stride:  # only for stateless detectors (HOG), which are slow
                continue
            start = time.perf_counter()
            found = detector.detect(image)
            times.append(time.perf_counter() - start)
            if i < skip:
                continue
            people = truth.boxes_at(i)
            boxes = list(people.values())
            seen = [truth.visibility.get(k, {}).get(i, 1.0) for k in people]
            dets = [d.box for d in found]
            every.add_frame(i, dets, boxes, source.size, visibility=seen)
            big = [v if b[3] >= min_height else 0.0 for b, v in zip(boxes, seen, strict=True)]
            tall.add_frame(i, dets, boxes, source.size, visibility=big)
            seed_score.add_frame(i, dets, boxes, source.size, visibility=big)
        per_seed[str(seed)] = {
            "recall": round(seed_score.recall, 4),
            "precision": round(seed_score.precision, 4),
        }
    return {
        "detector": kind,
        "frame_stride": stride,
        "config": config.hog.model_dump() if kind == "hog" else config.bgcode.model_dump(),
        "ms_per_frame_median": round(1000 * statistics.median(times), 3),
        "ms_per_frame_p90": round(1000 * float(np.quantile(times, 0.9)), 3),
        "recall": round(tall.recall, 4),
        "precision": round(tall.precision, 4),
        "true_positives": tall.true_positives,
        "false_positives": tall.false_positives,
        "false_negatives": tall.false_negatives,
        "recall_all_sizes": round(every.recall, 4),
        "precision_all_sizes": round(every.precision, 4),
        "per_seed": per_seed,
    }


def _peer_hog(args: argparse.Namespace) -> dict[str, Any]:
    from ptzd.vision.detect.hog import hog_available

    if hog_available():
        return _score(
            "hog",
            args.seed_list,
            args.frames,
            args.skip,
            args.min_height,
            stride=args.hog_stride,
            hog_resize=args.hog_resize,
        )
    python = args.peer_python or str(REPO / ".venv-bench" / "bin" / "python")
    if not Path(python).exists():
        return {
            "detector": "hog",
            "unavailable": f"OpenCV {cv2.__version__} has no HOG and {python} does not exist",
        }
    cmd = [
        python,
        "-m",
        "bench.detect",
        "--only",
        "hog",
        "--seeds",
        args.seeds,
        "--frames",
        str(args.frames),
        "--skip",
        str(args.skip),
        "--min-height",
        str(args.min_height),
        "--json",
        "-",
    ]
    env = dict(os.environ, PYTHONPATH=str(REPO))
    done = subprocess.run(cmd, capture_output=True, text=True, cwd=REPO, env=env, timeout=3600)
    if done.returncode != 0:
        last = (done.stderr.strip().splitlines() or ["?"])[-1]
        return {"detector": "hog", "unavailable": f"peer run failed: {last}"}
    result: dict[str, Any] = json.loads(done.stdout)["results"][0]
    result["python"] = python
    return result


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--seeds", default="1,2,3")
    parser.add_argument("--frames", type=int, default=300)
    parser.add_argument("--skip", type=int, default=25, help="warm-up frames not scored")
    parser.add_argument("--min-height", type=int, default=36)
    parser.add_argument("--only", choices=["bgcode", "hog"], default=None)
    parser.add_argument("--peer-python", default=None)
    parser.add_argument("--hog-stride", type=int, default=10, help="HOG: every Nth frame")
    parser.add_argument(
        "--hog-resize", type=float, default=2.0, help="HOG: upscale (its window is 128 px tall)"
    )
    parser.add_argument("--json", default=str(REPO / "bench" / "results" / "detect.json"))
    args = parser.parse_args(argv)
    args.seed_list = [int(s) for s in args.seeds.split(",")]
    results = []
    if args.only in (None, "bgcode"):
        results.append(_score("bgcode", args.seed_list, args.frames, args.skip, args.min_height))
    if args.only == "hog":
        results.append(
            _score(
                "hog",
                args.seed_list,
                args.frames,
                args.skip,
                args.min_height,
                stride=args.hog_stride,
                hog_resize=args.hog_resize,
            )
        )
    elif args.only is None:
        results.append(_peer_hog(args))
    doc = {
        "benchmark": "detect",
        "scenes": args.seed_list,
        "frames_per_scene": args.frames,
        "size": [640, 480],
        "min_iou": 0.5,
        "min_height": args.min_height,
        "opencv": cv2.__version__,
        "note": "2 shared cores; timings are noisy. Medians.",
        "results": results,
    }
    if args.json == "-":
        print(json.dumps(doc))
        return 0
    Path(args.json).parent.mkdir(parents=True, exist_ok=True)
    Path(args.json).write_text(json.dumps(doc, indent=2) + "\n")
    header = ("recall", "prec", "R(all)", "P(all)", "ms med", "ms p90")
    print(f"{'detector':10s} " + " ".join(f"{h:>7s}" for h in header))
    for r in results:
        if "unavailable" in r:
            print(f"{r['detector']:10s} unavailable: {r['unavailable']}")
            continue
        keys = ("recall", "precision", "recall_all_sizes", "precision_all_sizes")
        values = [f"{r[k]:7.3f}" for k in keys]
        values += [f"{r[k]:7.2f}" for k in ("ms_per_frame_median", "ms_per_frame_p90")]
        print(f"{r['detector']:10s} " + " ".join(values))
    print(f"wrote {args.json}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
