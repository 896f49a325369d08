"""Closed-loop benchmark: the daemon driving the simulated dome (issue 5 targets).

Runs `ptzd sim` (virtual clock, real Pelco bytes over a pty) on synthetic scenes and on the
annotated vtest.avi pedestrians in bench/annotations (needs data/vtest.avi:
./scripts/fetch-vtest.sh), prints a table and writes bench/results/closed_loop.json.

Targets: centred (central cell of the 3x3 grid) >= 95 % of frames, in view 100 %,
frame-to-command latency p99 <= 40 ms, at most one zoom reversal per 10 s. Latency is wall
time from a frame being rendered to its command being written (tracker included); this
machine is shared, so latency numbers are noisy.

    .venv/bin/python -m bench.closed_loop [--seeds 0 1 2] [--duration 30] [--tracker-seeds 0]
        [--box-scale 1.3] [--box-width 1.3] [--thermal-seeds 0 1 2] [--walkers-of 0]
        [--jobs 2] [--no-vtest] [--against BASE.json]

`--walkers-of SEED` adds every walker of synthetic:SEED seen for at least 4 s, each
followed from the frame in which he is first well in view (`ptzd sim --target ID`): the
population an operator picks from in the soak, deterministic and in process.

`--box-scale F` plays the vtest cases with every annotated box (the initial one included)
F times as wide and tall about its centre, clipped to the frame: how much the outcome hangs
on how tightly someone else drew the boxes (centring is scored on the box centres, which do
not move). `--box-width F` scales the widths alone (on top of `--box-scale`): a box drawn
round a walker mid-stride, legs apart, or with a margin at the sides only.

The outcome of a case is close to binary (the tracker stays on the target through a
crossing, or it does not) and which way it goes can hang on the particle filter's random
draws: `--tracker-seeds 0 1 2` runs every case once per tracker seed and the summary lines
give the mean over all runs and how many runs met the target, per class of case.
`--against BASE.json` (an earlier run's `--out`) lists the runs whose scores moved and
which of them turned across the target: a variant that turns as many runs each way is
churn, not a gain.
"""

from __future__ import annotations

import argparse
import asyncio
import itertools
import json
import statistics
import tempfile
from collections import Counter
from concurrent.futures import ProcessPoolExecutor
from pathlib import Path
from typing import Any

from ptzd.closed_loop import ClosedLoopOptions, run_closed_loop
from ptzd.config import validate_config

ROOT = Path(__file__).resolve().parents[1]
VTEST = ROOT / "data" / "vtest.avi"
# `--walkers-of`: walkers seen for less than this many frames (4 s at 25 fps) are left out
WALKER_MIN_FRAMES = 100


def cases(
    seeds: list[int],
    box_scale: float = 1.0,
    scaled_dir: Path | None = None,
    thermal_seeds: tuple[int, ...] = (),
    vtest: bool = True,
    box_width: float = 1.0,
) -> list[tuple[str, str, str | None, int | None]]:
    """(name, source, ground truth, target) per case; with `box_scale` != 1 (or
    `box_width` != 1: widths alone) the vtest annotations are written, boxes scaled, under
    `scaled_dir` and played from there.
    `thermal_seeds`: the same synthetic scenes seen by a thermal camera (`thermal:SEED`);
    `vtest`: the annotated vtest.avi tracks too, if the video is here."""
    out: list[tuple[str, str, str | None, int | None]] = [
        (f"synthetic:{s}", f"synthetic:{s}", None, None) for s in seeds
    ]
    out += [(f"thermal:{s}", f"synthetic-thermal:{s}", None, None) for s in thermal_seeds]
    if vtest and VTEST.exists():
        for gt in sorted((ROOT / "bench" / "annotations").glob("vtest_*.json")):
            doc = json.loads(gt.read_text())
            if box_scale != 1.0 or box_width != 1.0:
                if scaled_dir is None:
                    raise ValueError("box_scale needs a directory for the scaled annotations")
                gt = scaled_dir / gt.name
                gt.write_text(json.dumps(scale_boxes(doc, box_scale, box_width)))
            for track in doc["tracks"]:
                out.append((f"vtest#{track['id']}", str(VTEST), str(gt), int(track["id"])))
    return out


def walker_cases(
    seeds: list[int], min_frames: int = WALKER_MIN_FRAMES
) -> list[tuple[str, str, None, int]]:
    """Every walker of each synthetic scene who stays at least `min_frames` frames after he
    is first well in view (`walker:SEED/ID`): whom an operator could pick, as the soak's does,
    rather than the one walker `pick_walker` chooses."""
    from ptzd.closed_loop import first_well_visible
    from ptzd.errors import UsageError
    from ptzd.sim.sources import open_wide_source

    out: list[tuple[str, str, None, int]] = []
    for seed in seeds:
        gt = open_wide_source(f"synthetic:{seed}").ground_truth
        assert gt is not None  # a synthetic scene carries its ground truth
        for tid, frames in sorted(gt.tracks.items()):
            try:
                start = first_well_visible(gt, tid)
            except UsageError:
                continue
            if sum(1 for f in frames if f >= start) >= min_frames:
                out.append((f"walker:{seed}/{tid}", f"synthetic:{seed}", None, tid))
    return out


def scale_boxes(doc: dict[str, Any], factor: float, width: float = 1.0) -> dict[str, Any]:
    """A ground-truth document with every box `factor` times the size (and `width` times
    wider again) about its centre, clipped to the frame (`size`)."""
    frame_w, frame_h = doc["size"]
    out: dict[str, Any] = json.loads(json.dumps(doc))
    for track in out["tracks"]:
        for frame, box in track["frames"].items():
            if box is None:
                continue
            x, y, w, h = box
            cx, cy = x + w / 2, y + h / 2
            half_w, half_h = w * factor * width / 2, h * factor / 2
            x0, y0 = max(0.0, cx - half_w), max(0.0, cy - half_h)
            x1, y1 = min(frame_w, cx + half_w), min(frame_h, cy + half_h)
            scaled = (x0, y0, x1 - x0, y1 - y0)
            track["frames"][frame] = [round(v, 2) for v in scaled]
    return out


async def run_case(spec: str, gt: str | None, target: int | None, duration: float,
                   record: Path | None, tracker_seed: int = 0,
                   overrides: dict[str, Any] | None = None) -> dict[str, Any]:  # fmt: skip
    raw: dict[str, Any] = json.loads(json.dumps(overrides or {}))
    raw.setdefault("tracker", {})["seed"] = tracker_seed
    options = ClosedLoopOptions(
        config=validate_config(raw, environ={}),
        spec=spec,
        is_video=gt is not None,
        gt_path=gt,
        target=target,
        duration=duration,
        record=record,
        virtual=True,
    )
    return await run_closed_loop(options)


MISSES_HEADER = "uncentred T/O/L/other"
_TRACKER_STATES = ("tracking", "occluded", "lost")  # T/O/L


def misses(by_state: dict[str, int]) -> str:
    """Uncentred frames while tracking / occluded / lost / anything else (searching, going
    home, dropped), as `T/O/L/other`."""
    main = [by_state.get(s, 0) for s in _TRACKER_STATES]
    other = sum(n for s, n in by_state.items() if s not in _TRACKER_STATES)
    return "/".join(str(n) for n in [*main, other])


def summarise(rows: list[dict[str, Any]]) -> dict[str, dict[str, Any]]:
    """Per class of case (synthetic, thermal, walker, vtest): runs, mean centred / in view, targets
    met, and the uncentred frames summed by tracker state."""
    out: dict[str, dict[str, Any]] = {}
    for kind in ("synthetic", "thermal", "walker", "vtest"):
        mine = [r for r in rows if r["case"].startswith(kind)]
        if not mine:
            continue
        out[kind] = {
            "runs": len(mine),
            "centred_mean": round(statistics.fmean(r["centred"] for r in mine), 4),
            "in_view_mean": round(statistics.fmean(r["in_view"] for r in mine), 4),
            "met": sum(meets_target(r) for r in mine),
            "uncentred_by_state": dict(
                sum((Counter(r.get("uncentred_by_state", {})) for r in mine), Counter())
            ),
        }
        sizes = [r["size_err_median"] for r in mine if r.get("size_err_median") is not None]
        if sizes:
            # the runs' own medians, so one run's long miss does not weigh for the rest
            out[kind]["size_err_median"] = round(statistics.median(sizes), 4)
    return out


def meets_target(row: dict[str, Any]) -> bool:
    """Whether a run met the centring targets: centred >= 95 % of frames, in view in all."""
    return bool(row["centred"] >= 0.95 and row["in_view"] >= 1.0)


# What changed_runs() reads of a row: which run it is, and its scores.
RUN_KEYS = frozenset({"case", "tracker_seed", "centred", "in_view"})


def changed_runs(
    base: list[dict[str, Any]], rows: list[dict[str, Any]], tolerance: float = 0.004
) -> list[dict[str, Any]]:
    """The runs (case and tracker seed in both) whose centred or in-view fraction moved by
    more than `tolerance` from `base`'s, each with both scores and `turn`: "met" (now meets
    the target), "missed" (no longer does) or "" (same side of it)."""
    before = {(r["case"], r["tracker_seed"]): r for r in base}
    out = []
    for row in rows:
        old = before.get((row["case"], row["tracker_seed"]))
        if old is None:
            continue
        moved = max(abs(row[k] - old[k]) for k in ("centred", "in_view"))
        if moved <= tolerance:
            continue
        was, now = meets_target(old), meets_target(row)
        out.append({"case": row["case"], "tracker_seed": row["tracker_seed"],
                    "centred": [old["centred"], row["centred"]],
                    "in_view": [old["in_view"], row["in_view"]],
                    "turn": "" if was == now else ("met" if now else "missed")})  # fmt: skip
    return out


def run_row(name: str, spec: str, gt: str | None, target: int | None, tracker_seed: int,
            args: argparse.Namespace) -> dict[str, Any]:  # fmt: skip
    """One case with one tracker seed: the table row."""
    record = None
    if args.record:
        record = args.record / f"{name.replace(':', '_').replace('#', '_')}_t{tracker_seed}"
    report = asyncio.run(
        run_case(spec, gt, target, args.duration, record, tracker_seed, args.override)
    )
    latency = report["latency_ms"]
    return {
        "case": name,
        "tracker_seed": tracker_seed,
        "frames": report["frames_scored"],
        "centred": report["centred_fraction"],
        "in_view": report["in_view_fraction"],
        "size_err_median": report["size_error_median"],
        "latency_p50_ms": latency["p50_ms"],
        "latency_p99_ms": latency["p99_ms"],
        "reversals": report["zoom_reversals"],
        "max_reversals_per_10s": report["max_reversals_per_10s"],
        "dropped": report["frames_dropped"],
        "uncentred_by_state": report["uncentred_by_state"],
    }


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--seeds", type=int, nargs="*", default=[0, 1, 2])
    parser.add_argument("--duration", type=float, default=30.0)
    parser.add_argument("--record", type=Path, help="keep each run's records under this dir")
    parser.add_argument("--tracker-seeds", type=int, nargs="*", default=[0])
    parser.add_argument(
        "--thermal-seeds",
        type=int,
        nargs="*",
        default=[],
        help="also these synthetic scenes as a thermal camera sees them (for --override "
        '\'{"tracker": {"kind": "rf"}}\')',
    )
    parser.add_argument(
        "--walkers-of",
        type=int,
        nargs="*",
        default=[],
        metavar="SEED",
        help="also every walker of these synthetic scenes seen for at least "
        f"{WALKER_MIN_FRAMES} frames (cases walker:SEED/ID, a class of their own)",
    )
    parser.add_argument(
        "--override",
        type=json.loads,
        default={},
        metavar="JSON",
        help='config overrides, e.g. \'{"control": {"feedforward": 0}}\'',
    )
    parser.add_argument(
        "--box-scale", type=float, default=1.0, help="vtest boxes this many times as large"
    )
    parser.add_argument(
        "--box-width", type=float, default=1.0, help="vtest boxes this many times as wide"
    )
    parser.add_argument("--no-vtest", action="store_true", help="leave out the vtest.avi tracks")
    parser.add_argument(
        "--jobs",
        type=int,
        default=1,
        help="runs side by side in this many processes (scores are the same; latencies are "
        "then measured on a busier machine)",
    )
    parser.add_argument(
        "--against",
        type=Path,
        metavar="BASE.json",
        help="also list the runs whose scores differ from this earlier --out's (same case "
        "and tracker seed): with outcomes this close to binary, which runs turned, not "
        "only how many met the target",
    )
    parser.add_argument("--out", type=Path, default=ROOT / "bench" / "results" / "closed_loop.json")
    args = parser.parse_args()
    base_rows = None
    if args.against is not None:
        # read before the runs: a bad base found after them would lose their results
        try:
            base_rows = json.loads(args.against.read_text())["rows"]
            if not all(row.keys() >= RUN_KEYS for row in base_rows):
                raise ValueError(f"a row lacks one of {sorted(RUN_KEYS)}")
        except (OSError, ValueError, KeyError, TypeError, AttributeError) as exc:
            parser.error(f"--against {args.against}: not a closed_loop result ({exc})")
    if not 0.2 <= args.box_scale <= 5.0:
        parser.error(f"--box-scale must be in [0.2, 5], got {args.box_scale}")
    if not 0.2 <= args.box_width <= 5.0:
        parser.error(f"--box-width must be in [0.2, 5], got {args.box_width}")
    if not 1 <= args.jobs <= 64:
        parser.error(f"--jobs must be in [1, 64], got {args.jobs}")
    with tempfile.TemporaryDirectory(prefix="ptzd-gt-") as scaled_dir:
        listed = cases(
            args.seeds,
            args.box_scale,
            Path(scaled_dir),
            tuple(args.thermal_seeds),
            vtest=not args.no_vtest,
            box_width=args.box_width,
        )
        runs = [
            (name, spec, gt, target, tracker_seed, args)
            for (name, spec, gt, target), tracker_seed in itertools.product(
                listed + walker_cases(args.walkers_of), args.tracker_seeds
            )
        ]
        if args.jobs == 1:
            rows = [run_row(*run) for run in runs]
        else:
            # each run is deterministic on the virtual clock, so running them side by side
            # changes nothing but the (wall-clock) latency figures
            with ProcessPoolExecutor(max_workers=args.jobs) as pool:
                rows = list(pool.map(run_row, *zip(*runs, strict=True)))
    header = f"{'case':<14}{'tseed':>6}{'frames':>7}{'centred':>9}{'in view':>9}{'size err':>9}"
    header += f"{'p50 ms':>8}{'p99 ms':>8}{'rev':>5}{'rev/10s':>8}  {MISSES_HEADER}"
    print(header)
    for r in rows:
        print(
            f"{r['case']:<14}{r['tracker_seed']:>6}{r['frames']:>7}{r['centred']:>9.3f}{r['in_view']:>9.3f}"
            f"{(r['size_err_median'] or 0):>9.3f}{r['latency_p50_ms']:>8.1f}"
            f"{r['latency_p99_ms']:>8.1f}{r['reversals']:>5}{r['max_reversals_per_10s']:>8}"
            f"  {misses(r['uncentred_by_state'])}"
        )
    summary = summarise(rows)
    for kind, s in summary.items():
        size = f"{s['size_err_median']:.3f}" if "size_err_median" in s else "-"
        print(
            f"{kind:<10} runs {s['runs']:>3}  mean centred {s['centred_mean']:.3f}  in view "
            f"{s['in_view_mean']:.3f}  target met (centred >= 0.95, in view 1.0) "
            f"{s['met']}/{s['runs']}; size err {size}; "
            f"{MISSES_HEADER} {misses(s['uncentred_by_state'])}"
        )
    changed = None
    if base_rows is not None:
        changed = changed_runs(base_rows, rows)
        print(f"against {args.against}: {len(changed)} runs changed")
        for c in changed:
            print(
                f"  {c['case']:<14}{c['tracker_seed']:>4}  centred {c['centred'][0]:.3f} -> "
                f"{c['centred'][1]:.3f}  in view {c['in_view'][0]:.3f} -> {c['in_view'][1]:.3f}"
                f"  {('now ' + c['turn']) if c['turn'] else ''}"
            )
        turned = Counter(c["turn"] for c in changed)
        print(f"  now meeting the target: {turned['met']}; no longer: {turned['missed']}")
    out = args.out
    out.parent.mkdir(parents=True, exist_ok=True)
    doc = {"duration_s": args.duration, "override": args.override,
           "box_scale": args.box_scale, "box_width": args.box_width,
           "summary": summary, "rows": rows}  # fmt: skip
    if changed is not None:
        doc["against"] = {"base": str(args.against), "changed": changed}
    out.write_text(json.dumps(doc, indent=2) + "\n")
    print(f"wrote {out}")


if __name__ == "__main__":
    main()
