"""bench/closed_loop.py: scaled annotation boxes, cases, summaries and run comparisons."""

from __future__ import annotations

import json
from pathlib import Path
from typing import Any

import pytest

from bench.closed_loop import cases, changed_runs, scale_boxes, summarise


def test_scale_boxes_keeps_centres_and_clips_to_the_frame() -> None:
    frames = {"0": [40, 20, 10, 40], "1": [0, 60, 10, 20]}
    doc: dict[str, Any] = {"size": [100, 80], "fps": 10.0, "tracks": [{"id": 1, "frames": frames}]}
    scaled = scale_boxes(doc, 1.5)
    assert scaled["tracks"][0]["frames"]["0"] == [37.5, 10.0, 15.0, 60.0]  # centre (45, 40)
    # at the corner: grown by half, then clipped to columns 0..100 and rows 0..80
    assert scaled["tracks"][0]["frames"]["1"] == [0.0, 55.0, 12.5, 25.0]
    assert doc["tracks"][0]["frames"]["0"] == [40, 20, 10, 40]  # the input is left alone


def test_scale_boxes_can_widen_alone() -> None:
    frames = {"0": [40, 20, 10, 40], "1": [95, 20, 4, 40]}
    doc: dict[str, Any] = {"size": [100, 80], "fps": 10.0, "tracks": [{"id": 1, "frames": frames}]}
    wide = scale_boxes(doc, 1.0, width=1.3)["tracks"][0]["frames"]
    assert wide["0"] == [38.5, 20.0, 13.0, 40.0]  # centre (45, 40), height kept
    assert wide["1"] == [94.4, 20.0, 5.2, 40.0]  # just inside: 94.4 + 5.2 < 100
    both = scale_boxes(doc, 1.5, width=1.2)["tracks"][0]["frames"]
    assert both["0"] == [36.0, 10.0, 18.0, 60.0]


def test_cases_play_scaled_copies_of_the_annotations(tmp_path: Path) -> None:
    plain = [c for c in cases([]) if c[2] is not None]
    if not plain:
        pytest.skip("data/vtest.avi is not here (./scripts/fetch-vtest.sh)")
    scaled = [c for c in cases([], 1.3, tmp_path) if c[2] is not None]
    assert [c[0] for c in scaled] == [c[0] for c in plain]
    assert all(Path(c[2] or "").parent == tmp_path for c in scaled)
    with pytest.raises(ValueError, match="directory"):
        cases([], 1.3)
    (tmp_path / "wide").mkdir()
    widened = [c for c in cases([], 1.0, tmp_path / "wide", box_width=1.3) if c[2] is not None]
    assert [c[0] for c in widened] == [c[0] for c in plain]
    with pytest.raises(ValueError, match="directory"):
        cases([], box_width=1.3)


def test_thermal_cases_are_their_own_class() -> None:
    assert cases([1], thermal_seeds=(3,), vtest=False) == [
        ("synthetic:1", "synthetic:1", None, None),
        ("thermal:3", "synthetic-thermal:3", None, None),
    ]
    listed = cases([1], thermal_seeds=(3,))
    assert listed[:2] == [
        ("synthetic:1", "synthetic:1", None, None),
        ("thermal:3", "synthetic-thermal:3", None, None),
    ]
    rows = [{"case": "synthetic:1", "centred": 1.0, "in_view": 1.0},
            {"case": "thermal:3", "centred": 0.5, "in_view": 1.0,
             "uncentred_by_state": {"occluded": 3, "lost": 2}}]  # fmt: skip
    summary = summarise(rows)
    assert summary["synthetic"]["met"] == 1 and summary["synthetic"]["runs"] == 1
    assert summary["thermal"] == {"runs": 1, "centred_mean": 0.5, "in_view_mean": 1.0, "met": 0,
                                  "uncentred_by_state": {"occluded": 3, "lost": 2}}  # fmt: skip


def test_uncentred_frames_are_summed_by_state_per_class() -> None:
    from bench.closed_loop import misses

    rows = [{"case": "synthetic:1", "centred": 0.9, "in_view": 1.0,
             "uncentred_by_state": {"tracking": 4, "occluded": 1}},
            {"case": "synthetic:2", "centred": 0.8, "in_view": 1.0,
             "uncentred_by_state": {"tracking": 1, "searching": 2, "none": 1}}]  # fmt: skip
    by_state = summarise(rows)["synthetic"]["uncentred_by_state"]
    assert by_state == {"tracking": 5, "occluded": 1, "searching": 2, "none": 1}
    assert misses(by_state) == "5/1/0/3"  # tracking / occluded / lost / the rest


def test_walker_cases_are_the_walkers_seen_long_enough() -> None:
    from bench.closed_loop import walker_cases
    from ptzd.closed_loop import first_well_visible
    from ptzd.errors import UsageError
    from ptzd.sim.sources import open_wide_source

    gt = open_wide_source("synthetic:0").ground_truth
    assert gt is not None
    listed = walker_cases([0], min_frames=100)
    ids = {target for _, _, _, target in listed}
    assert all(spec == "synthetic:0" and truth is None for _, spec, truth, _ in listed)
    assert [name for name, *_ in listed] == [f"walker:0/{t}" for t in sorted(ids)]
    for tid, frames in gt.tracks.items():
        try:
            left = sum(1 for f in frames if f >= first_well_visible(gt, tid))
        except UsageError:
            left = 0  # never well in view
        assert (tid in ids) == (left >= 100), tid
    assert len(ids) > 20 and len(walker_cases([0], min_frames=400)) < len(ids)
    rows = [{"case": "walker:0/4", "centred": 0.5, "in_view": 1.0}]
    assert summarise(rows) == {
        "walker": {
            "runs": 1,
            "centred_mean": 0.5,
            "in_view_mean": 1.0,
            "met": 0,
            "uncentred_by_state": {},
        }
    }


@pytest.mark.slow
def test_runs_side_by_side_score_as_one_after_another(tmp_path: Path) -> None:
    """`--jobs 2` spreads the runs over processes; on the virtual clock every score is the
    same as running them in turn, and the rows keep the cases' order."""
    import subprocess
    import sys

    root = Path(__file__).resolve().parents[1]
    docs = []
    for jobs in (1, 2):
        out = tmp_path / f"jobs{jobs}.json"
        command = [sys.executable, "-m", "bench.closed_loop", "--seeds", "3", "4"]
        command += ["--duration", "2", "--no-vtest", "--jobs", str(jobs), "--out", str(out)]
        if jobs == 2:
            command += ["--against", str(tmp_path / "jobs1.json")]
        done = subprocess.run(
            command,
            cwd=root,
            check=True,
            capture_output=True,
            text=True,
            timeout=110,
        )
        docs.append(json.loads(out.read_text()))
    assert "0 runs changed" in done.stdout
    assert docs[1]["against"] == {"base": str(tmp_path / "jobs1.json"), "changed": []}
    scores = [[(r["case"], r["centred"], r["in_view"], r["frames"]) for r in d["rows"]]
              for d in docs]  # fmt: skip
    assert [case for case, *_ in scores[0]] == ["synthetic:3", "synthetic:4"]
    assert scores[0] == scores[1]


def _run(case: str, seed: int, centred: float, in_view: float = 1.0) -> dict[str, Any]:
    return {"case": case, "tracker_seed": seed, "centred": centred, "in_view": in_view}


def test_changed_runs_are_those_that_moved_and_say_which_way_they_turned() -> None:
    base = [_run("synthetic:1", 0, 1.0), _run("synthetic:1", 1, 0.96),
            _run("synthetic:5", 0, 0.84), _run("synthetic:8", 0, 0.97),
            _run("synthetic:9", 0, 0.99)]  # fmt: skip
    rows = [_run("synthetic:1", 0, 0.998),  # within the tolerance: not listed
            _run("synthetic:1", 1, 0.98),  # moved, met both times
            _run("synthetic:5", 0, 1.0),  # now meets the target
            _run("synthetic:8", 0, 0.97, in_view=0.99),  # left the view: no longer meets it
            _run("synthetic:9", 1, 0.5)]  # fmt: skip  # (not in base: another tracker seed)
    changed = changed_runs(base, rows)
    assert [(c["case"], c["tracker_seed"], c["turn"]) for c in changed] == [
        ("synthetic:1", 1, ""),
        ("synthetic:5", 0, "met"),
        ("synthetic:8", 0, "missed"),
    ]
    assert changed[1]["centred"] == [0.84, 1.0] and changed[2]["in_view"] == [1.0, 0.99]
    assert changed_runs(base, base) == []


def test_the_summary_gives_the_median_of_the_runs_size_errors() -> None:
    rows = [{**_run("synthetic:1", 0, 1.0), "size_err_median": 0.1},
            {**_run("synthetic:2", 0, 1.0), "size_err_median": 0.5},
            {**_run("synthetic:3", 0, 1.0), "size_err_median": 0.2},
            {**_run("synthetic:4", 0, 1.0), "size_err_median": None}]  # fmt: skip
    assert summarise(rows)["synthetic"]["size_err_median"] == 0.2  # None: nothing measured


def test_a_bad_against_file_is_refused_before_anything_runs(tmp_path: Path) -> None:
    import subprocess
    import sys

    root = Path(__file__).resolve().parents[1]
    bad = tmp_path / "bad.json"
    bad.write_text('{"summary": {}}')
    seedless = tmp_path / "seedless.json"  # a row that cannot be matched to a run
    seedless.write_text('{"rows": [{"case": "synthetic:1", "centred": 1.0, "in_view": 1.0}]}')
    for path in (bad, seedless, tmp_path / "missing.json"):
        done = subprocess.run(
            [sys.executable, "-m", "bench.closed_loop", "--against", str(path)],
            cwd=root,
            capture_output=True,
            text=True,
            timeout=60,
        )
        assert done.returncode == 2
        assert f"--against {path}: not a closed_loop result" in done.stderr
