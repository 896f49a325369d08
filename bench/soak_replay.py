"""Every operator selection of a real-time soak, played again in process (issue 9's centring).

A 1-hour soak (`ptzd soak --minutes 60 --report DIR`) takes an hour and its operator picks
whom he likes; each of its selections is played again here, deterministic, on the virtual
clock, in about 8 s of CPU: `ptzd sim --scene synthetic:0 --gt GT --target ID` with

- the dome starting at the pose the soak's dome had when the selected frame was rendered
  (`[sim] start_pan`, `start_tilt`, `start_hfov`, from the soak's `sim/camera.jsonl`),
- the ground truth the walker's track from the selected scene frame on (so the run starts
  there, the tracker on his box in the first view, as the soak's operator boxed him),
- the soak's regime: no pose with the frames (the daemon dead-reckons), JPEG frames, the
  soak's capture latency;

and centring counted as the soak counts it, from `SETTLE_FRAMES` after the selection.
What it does not have: the real-time frame timing, and the daemon's state from the target
before (a selection made while the dome still turned after the previous walker).

    .venv/bin/python -m bench.soak_replay SOAK_DIR [--duration 20] [--tracker-seeds 0]
        [--override JSON] [--frames F ...] [--jobs 2] [--out bench/results/soak_replay.json]

Prints a row per selection (soak frame, walker, the soak's own centring, the replay's) and
the means, and writes JSON.
"""

from __future__ import annotations

import argparse
import asyncio
import itertools
import json
import statistics
import tempfile
from concurrent.futures import ProcessPoolExecutor
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from bench.closed_loop import ROOT, meets_target, run_case
from ptzd.closed_loop import in_central_cell
from ptzd.config import merge_tables
from ptzd.sim.groundtruth import GroundTruth, save_ground_truth
from ptzd.soak import SCENE, SETTLE_FRAMES, SIM_CAMERA_LATENCY_S

# the soak's camera: frames JPEG-compressed over MJPEG, no pose reported with them
SOAK_REGIME: dict[str, Any] = {
    "sim": {"report_pose": False, "compress_frames": True},
    "capture": {"latency_s": SIM_CAMERA_LATENCY_S},
}


@dataclass(frozen=True)
class Selection:
    """One operator selection of a soak: its frame, the walker, and the dome's pose then."""

    frame: int  # the soak's rendered-frame index
    walker: int
    video_frame: int  # the scene frame shown
    pan: float
    tilt: float
    hfov: float
    soak_centred: float | None  # what the soak measured for it
    soak_in_view: float | None


def soak_selections(soak_dir: Path) -> list[Selection]:
    """The selections of a real-time soak's report with the dome's pose at each: the
    `sim/camera.jsonl` record of the selected frame's render time."""
    report = json.loads((soak_dir / "report.json").read_text())
    wanted = {int(s["frame"]): int(s["walker"]) for s in report.get("selections", [])}
    scores = {int(c["frame"]): c for c in report.get("centring", {}).get("selections", [])}
    shown: dict[int, tuple[float, int]] = {}  # frame -> (render time, scene frame)
    with (soak_dir / "sim" / "groundtruth_view.jsonl").open(encoding="utf-8") as lines:
        for line in lines:
            record = json.loads(line)
            if int(record["frame"]) in wanted:
                shown[int(record["frame"])] = (float(record["t"]), int(record["video_frame"]))
    times = {t: frame for frame, (t, _) in shown.items()}
    poses: dict[int, dict[str, Any]] = {}
    with (soak_dir / "sim" / "camera.jsonl").open(encoding="utf-8") as lines:
        for line in lines:
            record = json.loads(line)
            for t, frame in times.items():
                if frame not in poses and abs(float(record["t"]) - t) < 1e-3:
                    poses[frame] = record
    out = []
    for frame in sorted(wanted):
        if frame not in shown or frame not in poses:
            continue  # the records were cut short (a soak stopped early)
        pose, score = poses[frame], scores.get(frame, {})
        out.append(Selection(frame, wanted[frame], shown[frame][1], float(pose["pan"]),
                             float(pose["tilt"]), float(pose["hfov"]), score.get("centred"),
                             score.get("in_view")))  # fmt: skip
    return out


def walker_truth(truth: GroundTruth, walker: int, first: int, late: int = 0) -> GroundTruth:
    """`truth` with `walker`'s track starting at scene frame `first` (the others whole).

    With `late` N > 0 it starts N frames later, with the box of frame `first`: a box that
    reaches the tracker N frames after the picture it was drawn on, put on the newest
    frame as it is (what the daemon did before it remembered frames to catch up from)."""
    own = {f: b for f, b in truth.tracks[walker].items() if f >= first + late}
    if late and first in truth.tracks[walker] and first + late in own:
        own[first + late] = truth.tracks[walker][first]
    tracks = {tid: (own if tid == walker else frames) for tid, frames in truth.tracks.items()}
    return GroundTruth(truth.size, truth.fps, tracks=tracks, visibility=truth.visibility)


def settled_centring(per_frame: list[dict[str, Any]], settle: int) -> tuple[float, float]:
    """(centred, in view) over the frames from `settle` on, as the soak counts them."""
    frames = per_frame[settle:] or per_frame
    centred = in_view = 0
    for f in frames:
        ex, ey = f["ex"], f["ey"]
        if ex is None or ey is None or not (abs(ex) <= 1 and abs(ey) <= 1):
            continue
        in_view += 1
        # (per_frame offsets are in half views: the view is [-1, 1] x [-1, 1])
        centred += in_central_cell(ex + 1.0, ey + 1.0, 2, 2)
    return centred / max(len(frames), 1), in_view / max(len(frames), 1)


def replay_row(selection: Selection, gt_path: str, tracker_seed: int,
               args: argparse.Namespace) -> dict[str, Any]:  # fmt: skip
    """One selection with one tracker seed: the table row."""
    pose = {"sim": {"start_pan": selection.pan, "start_tilt": selection.tilt,
                    "start_hfov": selection.hfov}}  # fmt: skip
    overrides = merge_tables(merge_tables(SOAK_REGIME, pose), args.override)
    record = None
    if args.record:
        record = args.record / f"{selection.frame}_w{selection.walker}_t{tracker_seed}"
    report = asyncio.run(
        run_case(SCENE, gt_path, selection.walker, args.duration, record, tracker_seed, overrides)
    )
    centred, in_view = settled_centring(report["per_frame"], SETTLE_FRAMES)
    return {
        "frame": selection.frame,
        "walker": selection.walker,
        "video_frame": selection.video_frame,
        "tracker_seed": tracker_seed,
        "soak_centred": selection.soak_centred,
        "soak_in_view": selection.soak_in_view,
        "centred": round(centred, 4),
        "in_view": round(in_view, 4),
        "uncentred_by_state": report["uncentred_by_state"],
    }


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("soak_dir", type=Path, help="a real-time soak's --report directory")
    parser.add_argument("--duration", type=float, default=20.0)
    parser.add_argument("--tracker-seeds", type=int, nargs="*", default=[0])
    parser.add_argument("--frames", type=int, nargs="*", help="only these selections (soak frames)")
    parser.add_argument("--override", type=json.loads, default={}, metavar="JSON",
                        help="config overrides, per section over the soak's regime")  # fmt: skip
    parser.add_argument("--record", type=Path, help="keep each run's records under this dir")
    parser.add_argument("--jobs", type=int, default=1)
    parser.add_argument("--late-frames", type=int, default=0, metavar="N",
                        help="start each run N frames after the selection, on the box the "
                        "operator drew N frames before (a box put on the newest frame as it "
                        "is)")  # fmt: skip
    parser.add_argument("--out", type=Path, default=ROOT / "bench" / "results" / "soak_replay.json")
    args = parser.parse_args(argv)
    if not 1 <= args.jobs <= 64:
        parser.error(f"--jobs must be in [1, 64], got {args.jobs}")
    if not 0 <= args.late_frames <= 100:
        parser.error(f"--late-frames must be in [0, 100], got {args.late_frames}")
    selections = soak_selections(args.soak_dir)
    if args.frames:
        wanted = set(args.frames)
        selections = [s for s in selections if s.frame in wanted]
    if not selections:
        parser.error(f"{args.soak_dir}: no selection with its records to replay")
    from ptzd.sim.sources import open_wide_source

    truth = open_wide_source(SCENE).ground_truth
    assert truth is not None  # a synthetic scene carries its ground truth
    with tempfile.TemporaryDirectory(prefix="ptzd-soak-replay-") as tmp:
        runs = []
        for selection, seed in itertools.product(selections, args.tracker_seeds):
            path = Path(tmp) / f"{selection.walker}_{selection.video_frame}.json"
            if not path.exists():
                save_ground_truth(
                    walker_truth(truth, selection.walker, selection.video_frame, args.late_frames),
                    path,
                )
            runs.append((selection, str(path), seed, args))
        if args.jobs == 1:
            rows = [replay_row(*run) for run in runs]
        else:  # deterministic runs: side by side changes nothing
            with ProcessPoolExecutor(max_workers=args.jobs) as pool:
                rows = list(pool.map(replay_row, *zip(*runs, strict=True)))
    print(
        f"{'frame':>7}{'walker':>7}{'scene':>7}{'tseed':>6}{'soak':>8}{'replay':>8}{'in view':>9}"
    )
    for r in rows:
        soak = "-" if r["soak_centred"] is None else f"{r['soak_centred']:.3f}"
        print(f"{r['frame']:>7}{r['walker']:>7}{r['video_frame']:>7}{r['tracker_seed']:>6}"
              f"{soak:>8}{r['centred']:>8.3f}{r['in_view']:>9.3f}")  # fmt: skip
    summary = {
        "runs": len(rows),
        "centred_mean": round(statistics.fmean(r["centred"] for r in rows), 4),
        "in_view_mean": round(statistics.fmean(r["in_view"] for r in rows), 4),
        "met": sum(meets_target(r) for r in rows),
    }
    soaked = [r["soak_centred"] for r in rows if r["soak_centred"] is not None]
    if soaked:
        summary["soak_centred_mean"] = round(statistics.fmean(soaked), 4)
    soak_said = f" (the soak itself: {summary['soak_centred_mean']:.3f})" if soaked else ""
    print(f"replayed {summary['runs']} runs: mean centred {summary['centred_mean']:.3f}, in view "
          f"{summary['in_view_mean']:.3f}, {summary['met']} met the target{soak_said}")  # fmt: skip
    args.out.parent.mkdir(parents=True, exist_ok=True)
    doc = {"soak_dir": str(args.soak_dir), "duration_s": args.duration,
           "override": args.override, "summary": summary, "rows": rows}  # fmt: skip
    args.out.write_text(json.dumps(doc, indent=2) + "\n")
    print(f"wrote {args.out}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
