"""The soak harness: option checks, /proc sampling, plots, and real (short) soaks.

The CI soak (`-m slow`) runs the three processes for real with all four faults and checks
the report: clean exit, dome left stopped, no leaks, every fault recovered as documented.
"""

from __future__ import annotations

import asyncio
import itertools
import json
import mmap
import os
import subprocess
import sys
import threading
import time
from pathlib import Path

import cv2
import numpy as np
import pytest

from ptzd.errors import UsageError
from ptzd.sim.groundtruth import GroundTruth
from ptzd.soak import (
    FAULTS,
    MqttWatcher,
    SoakOptions,
    _probe_loop,
    dome_still,
    draw_plots,
    operator_choice,
    proc_sample,
    rss_trend,
    selection_centring,
    shown_record,
    virtual_report,
)


def test_options_reject_unknown_faults_and_faults_on_the_virtual_clock(tmp_path: Path) -> None:
    with pytest.raises(UsageError, match="unknown fault"):
        SoakOptions(minutes=1, report_dir=tmp_path, faults=("meteor",))
    with pytest.raises(UsageError, match="virtual-clock"):
        SoakOptions(minutes=1, report_dir=tmp_path, faults=FAULTS[:1], virtual_clock=True)
    with pytest.raises(UsageError, match="minutes"):
        SoakOptions(minutes=0, report_dir=tmp_path)
    with pytest.raises(UsageError, match="--fps must be"):
        SoakOptions(minutes=1, report_dir=tmp_path, virtual_clock=True, fps=0)
    with pytest.raises(UsageError, match="--fps needs --virtual-clock"):
        SoakOptions(minutes=1, report_dir=tmp_path, fps=10)


def test_proc_sample_sees_a_new_file_descriptor() -> None:
    before = proc_sample(os.getpid())
    fd = os.open(os.devnull, os.O_RDONLY)
    try:
        after = proc_sample(os.getpid())
    finally:
        os.close(fd)
    assert after["fds"] == before["fds"] + 1
    assert 5 < before["rss_mb"] < 10_000


def test_proc_sample_sees_the_heap_grow_in_the_anonymous_part() -> None:
    before = proc_sample(os.getpid())
    # a private anonymous mapping of its own (shared ones count as RssShmem), not malloc's:
    # in the full suite malloc once served 64 MB from free pages earlier tests had left
    # resident, and RssAnon did not move. Zero pages are not resident until written.
    block = mmap.mmap(-1, 64 * 1024 * 1024, flags=mmap.MAP_PRIVATE | mmap.MAP_ANONYMOUS)
    block[::4096] = b"x" * len(range(0, len(block), 4096))
    after = proc_sample(os.getpid())
    block.close()
    assert 0 < before["rss_anon_mb"] < before["rss_mb"]
    assert after["rss_anon_mb"] - before["rss_anon_mb"] > 60


def test_plots_draw_every_sampled_series(tmp_path: Path) -> None:
    samples = [
        {"t": float(t), "rss_mb": 90 + t / 10, "fds": 11, "tasks": 16, "lag_ms": 0.2,
         "commands": t * 3, "mqtt_messages": t * 9}
        for t in range(0, 60, 2)
    ]  # fmt: skip
    draw_plots({"samples": samples, "faults": [{"at_s": 30.0}]}, tmp_path / "soak.png")
    image = cv2.imread(str(tmp_path / "soak.png"))
    assert image is not None and image.shape[0] == 6 * 150 + 20
    assert (image[:, :, 2] > 200).sum() > 0 and (image[:, :, 0] < 100).sum() > 0


def test_rss_trend_sees_a_leak_and_not_a_breathing_heap() -> None:
    # a steady daemon's heap: +-4 MB from sample to sample around 120 MB
    rng = np.random.default_rng(0)
    breathing = list(120.0 + rng.uniform(-4.0, 4.0, 120))
    start, end = rss_trend(breathing) or (0.0, 0.0)
    assert abs(end - start) < 1.5
    assert max(abs(b - a) for a, b in itertools.product(breathing[:3], breathing[-3:])) > 5
    leaking = [100.0 + 0.5 * i for i in range(40)]  # 0.5 MB per sample
    start, end = rss_trend(leaking) or (0.0, 0.0)
    assert end - start == pytest.approx(15.0)  # medians of the first and the last 10
    assert rss_trend([]) is None


def test_probe_counts_tasks_only_while_the_loop_runs_some(tmp_path: Path) -> None:
    path = tmp_path / "probe.jsonl"
    loop = asyncio.new_event_loop()
    probe = threading.Thread(target=_probe_loop, args=(loop, path, 0.05), daemon=True)
    probe.start()
    # first the loop runs callbacks but no task (as while `asyncio.run` winds down) ...
    loop.call_later(0.5, loop.stop)
    loop.run_forever()
    idle = len(path.read_text().splitlines())

    # ... then a main task and two more
    async def main() -> None:
        others = [asyncio.create_task(asyncio.sleep(0.6)) for _ in range(2)]
        await asyncio.gather(*others)

    loop.run_until_complete(main())
    loop.close()
    probe.join(timeout=2)
    samples = [json.loads(line) for line in path.read_text().splitlines()]
    assert idle >= 3 and all("tasks" not in s and s["lag_s"] < 0.5 for s in samples[:idle])
    counted = [s["tasks"] for s in samples[idle:] if "tasks" in s]
    assert len(counted) >= 3 and max(counted) == 3


@pytest.mark.slow
def test_virtual_clock_soak_probes_the_sim_process(tmp_path: Path) -> None:
    run = subprocess.run(
        [sys.executable, "-m", "ptzd", "soak", "--virtual-clock", "--minutes", "0.1",
         "--fps", "10", "--sample-s", "0.5", "--report", str(tmp_path)],
        capture_output=True, text=True, timeout=110,
    )  # fmt: skip
    report = json.loads((tmp_path / "report.json").read_text())
    checks = report["checks"]
    # a 9-second run is all start-up: its leak checks say nothing (see the test below)
    assert checks["clean_exit"] and checks["simulated_what_was_asked"], run.stderr[-2000:]
    assert checks["no_unhandled_exception"] and report["summary"]["exit_code"] == 0
    assert report["summary"]["simulated_s"] >= 6.0  # the 0.1 minutes asked for really ran
    # the dome streamed at the --fps asked for (the scene's own rate is 25)
    assert abs(report["summary"]["frames_processed"] - 10 * report["summary"]["simulated_s"]) <= 2
    assert report["summary"]["rss_mb_end"] > 20
    assert 0 < report["summary"]["rss_anon_mb_end"] < report["summary"]["rss_mb_end"]
    assert (tmp_path / "soak.png").exists()
    probe = [json.loads(line) for line in (tmp_path / "probe.jsonl").read_text().splitlines()]
    counted = [p["tasks"] for p in probe if "tasks" in p]
    assert counted and min(counted) >= 1


def test_the_watcher_notes_when_the_track_messages_name_another_tracker() -> None:
    now = [0.0]
    watcher = MqttWatcher(0, lambda: now[0])
    for now[0], payload in enumerate(
        (b'{"state":"searching","tracker":null}', b'{"state":"tracking","tracker":"color"}',
         b'{"tracker":"color"}', b"garbage{", b"[1]", b'{"tracker":"rf"}', b'{"tracker":"rf"}',
         b'{"tracker":"color"}'),
    ):  # fmt: skip
        watcher._note_tracker(payload)
    # a change is noted when it comes; nulls, repeats and bad payloads are not changes
    assert watcher.tracker_changes == [(1, "color"), (5, "rf"), (7, "color")]
    assert watcher.named_after(2.0, "rf") == 5
    assert watcher.named_after(5.0, "rf") is None  # only what came after
    assert watcher.named_after(0.0, "color") == 1 and watcher.named_after(4.0, "color") == 7


@pytest.mark.slow
@pytest.mark.timeout(200)
def test_ci_soak_with_every_fault(tmp_path: Path) -> None:
    started = time.monotonic()
    run = subprocess.run(
        [sys.executable, "-m", "ptzd", "soak", "--minutes", str(CI_SOAK_MINUTES),
         "--faults", ",".join(FAULTS), "--warmup-s", "120", "--report", str(tmp_path),
         "--max-heap-growth-mb", str(CI_HEAP_GROWTH_MB)],
        capture_output=True, text=True, timeout=195,
    )  # fmt: skip
    report = json.loads((tmp_path / "report.json").read_text())
    assert run.returncode == 0, json.dumps(
        {k: report[k] for k in ("checks", "faults", "summary")}, indent=1
    )
    assert [f["fault"] for f in report["faults"]] == list(FAULTS)
    assert all(f["recovered"] for f in report["faults"])
    night = next(f for f in report["faults"] if f["fault"] == "day-night")
    assert night["night_switch_s"] <= 15 and night["day_switch_s"] <= 15
    assert night["night_on_mqtt_s"] <= 15 and night["day_on_mqtt_s"] <= 15  # seen by the site
    # the leak checks start after the first night (the night tracker's one-time memory)
    assert report["summary"]["leak_checks_from_s"] >= night["ended_s"]
    summary = report["summary"]
    assert summary["daemon_exit_code"] == 0 and summary["last_motion_is_stop"]
    assert summary["rss_anon_growth_mb"] < CI_HEAP_GROWTH_MB
    assert summary["mqtt_messages"] > 100 and summary["frames"] > 500
    assert time.monotonic() - started < 195


CI_SOAK_MINUTES = 3.0
# The 5 MB goal is the 1-hour and 24-hour runs' (docs/reliability.md). In 3 minutes the window
# after warm-up is 90 s, and there the live heap follows the scenario (the background model
# is built while the dome stands and dropped when it moves; box-sized arrays follow the zoom):
# 60.3..75.3 MB within one such window, growth -3.9..+4.1 MB over healthy runs (+12.18 MB
# once, from the colour likelihood's cache of ended locks' arrays and malloc's fragmentation,
# both since fixed: docs/reliability.md). 10 MB still fails a leak of 4 KB a frame.
CI_HEAP_GROWTH_MB = 10.0


def test_virtual_soak_checks_catch_growth_and_leaks(tmp_path: Path) -> None:
    (tmp_path / "sim").mkdir()
    (tmp_path / "sim" / "report.json").write_text('{"duration_s": 600.0, "frames_processed": 6000}')
    (tmp_path / "sim.log").write_text('{"event": "daemon_stopped"}\n')
    (tmp_path / "probe.jsonl").write_text('{"lag_s": 0.001, "tasks": 12}\n')
    options = SoakOptions(minutes=10, report_dir=tmp_path, virtual_clock=True, warmup_s=30)

    def samples(
        anon_end: float, fds_end: int, tasks_end: int, files_growth: float = 0.0
    ) -> list[dict[str, object]]:
        out: list[dict[str, object]] = []
        for k in range(101):  # every 2 s for 200 s; start-up growth in the first 20 s
            f = k / 100
            anon = 80.0 + 100.0 * min(1.0, k / 10) + (anon_end - 180.0) * f
            files = 50.0 + files_growth * f  # pages of mapped libraries
            out.append({"t": 2.0 * k, "rss_mb": anon + files, "rss_anon_mb": anon,
                        "fds": 11 + round((fds_end - 11) * f),
                        "tasks": 12 + round((tasks_end - 12) * f)})  # fmt: skip
        return out

    steady = virtual_report(options, samples(181.0, 11, 12), 0, 200.0)
    assert steady["ok"] and steady["summary"]["rss_anon_growth_mb"] < 5.0
    # library pages mapped in as the run reaches new code are not a leak; the heap is
    libraries = virtual_report(options, samples(181.0, 11, 12, files_growth=20.0), 0, 200.0)
    assert libraries["ok"] and libraries["summary"]["rss_growth_mb"] > 10.0
    leaking = virtual_report(options, samples(190.0, 30, 40), 0, 200.0)
    checks = leaking["checks"]
    assert not leaking["ok"] and leaking["summary"]["rss_anon_growth_mb"] > 5.0
    assert not checks["heap_growth_below_limit"] and not checks["no_fd_leak"]
    assert not checks["no_task_leak"] and checks["clean_exit"]
    looser = SoakOptions(minutes=10, report_dir=tmp_path, virtual_clock=True, warmup_s=30,
                         max_heap_growth_mb=12.0)  # fmt: skip
    assert virtual_report(looser, samples(190.0, 11, 12), 0, 200.0)["ok"]
    with pytest.raises(UsageError, match="max-heap-growth-mb"):
        SoakOptions(minutes=1, report_dir=tmp_path, max_heap_growth_mb=0.0)
    short = SoakOptions(minutes=20, report_dir=tmp_path, virtual_clock=True)
    assert not virtual_report(short, samples(181.0, 11, 12), 0, 200.0)["checks"][
        "simulated_what_was_asked"
    ]
    (tmp_path / "sim.log").write_text("Traceback (most recent call last):\n")
    assert not virtual_report(options, samples(181.0, 11, 12), 0, 200.0)["ok"]


def test_selection_centring_counts_only_while_the_walker_is_in_the_scene() -> None:
    """Per selection: after the settle time, the frames in which the walker is in the scene
    at all; in view and centred (central cell of the 3x3 grid) are shares of those."""
    centre, edge = [300.0, 200.0, 40.0, 80.0], [560.0, 200.0, 40.0, 80.0]  # cx 320 / 580

    def line(frame: int, boxes: dict[str, list[float] | None]) -> str:
        return json.dumps({"t": frame / 25, "frame": frame, "boxes": boxes})

    lines = [line(f, {"1": centre}) for f in range(10)]  # settling: not counted
    lines += [line(f, {"1": centre}) for f in range(10, 16)]  # 6 centred
    lines += [line(f, {"1": edge}) for f in range(16, 18)]  # 2 in view, off-centre
    lines += [line(f, {"1": None}) for f in range(18, 20)]  # 2 lost from view
    lines += [line(f, {"2": centre}) for f in range(20, 30)]  # walker 1 left the scene
    lines += [line(f, {"1": edge}) for f in range(30, 34)]  # the scene loops: not counted
    lines += ["not json", json.dumps({"frame": 31})]  # skipped, not fatal
    lines += [line(f, {"2": None}) for f in range(40, 55)]  # walker 2 selected at 35
    selections: list[dict[str, object]] = [{"frame": 0, "walker": 1}, {"frame": 35, "walker": "2"}]
    result = selection_centring(lines, selections, 10)
    first, second = result["selections"]
    assert (first["frames"], first["in_view"], first["centred"]) == (10, 0.8, 0.6)
    assert (second["frames"], second["in_view"], second["centred"]) == (10, 0.0, 0.0)
    assert (result["frames"], result["in_view"], result["centred"]) == (20, 0.4, 0.3)


def test_the_operator_selects_the_biggest_walker_he_can_see() -> None:
    """Walker 1 is the biggest but behind a hedge at wide frame 7 (visibility 0.3): the
    operator takes walker 2; at frame 8 walker 1 is in the open and is taken; walker 3 is
    at the view's edge and too small, walker 4 has no visibility map (counted visible),
    walker 6 is taken only while no edge of his box lies on the view's border and while he
    stays in the scene long enough to be measured."""
    truth = GroundTruth((1000, 500), 25.0, tracks={}, visibility={1: {7: 0.3, 8: 1.0}, 2: {7: 1.0}})
    boxes: dict[str, list[float] | None] = {
        "1": [250.0, 100.0, 80.0, 200.0], "2": [300.0, 120.0, 40.0, 100.0],
        "3": [600.0, 100.0, 20.0, 25.0], "4": [100.0, 200.0, 20.0, 40.0], "5": None,
    }  # fmt: skip
    record = {"frame": 1507, "video_frame": 7, "boxes": boxes}
    assert operator_choice(record, truth) == ("2", boxes["2"])
    assert operator_choice({**record, "video_frame": 8}, truth) == ("1", boxes["1"])
    hidden = {**record, "boxes": {"1": boxes["1"], "3": boxes["3"]}}
    assert operator_choice(hidden, truth) is None  # nobody fit: no selection this time
    nobody_mapped = {**record, "boxes": {"4": boxes["4"]}}
    assert operator_choice(nobody_mapped, truth) == ("4", boxes["4"])
    # the biggest box, but cut off by the view's bottom edge (boxes are clipped to the view)
    cut_off = {**boxes, "6": [200.0, 380.0, 120.0, 100.0]}
    assert operator_choice({**record, "boxes": cut_off}, truth) == ("2", boxes["2"])
    inside = {**boxes, "6": [200.0, 370.0, 120.0, 100.0]}
    assert operator_choice({**record, "boxes": inside}, truth) == ("6", inside["6"])
    # walker 6 again, but he leaves the scene (his track ends) 100 frames on: too soon
    leaving = GroundTruth(
        (1000, 500), 25.0, tracks={6: dict.fromkeys(range(108), (0.0, 0.0, 10.0, 10.0))},
        visibility=truth.visibility,
    )  # fmt: skip
    assert operator_choice({**record, "boxes": inside}, leaving) == ("2", boxes["2"])


def test_dome_still_needs_the_same_pose_over_the_last_frames() -> None:
    pose = {"pan": 1.0, "tilt": -2.0, "hfov": 40.0}
    turning = [{**pose, "pan": 1.0 + 0.5 * i} for i in range(5)]
    assert dome_still([*turning, pose, pose, pose], 3)
    assert not dome_still([*turning, pose, pose, pose], 4)  # the pan changed 4 frames ago
    assert not dome_still([pose, pose], 3)  # too few frames to tell
    assert not dome_still([pose, pose, {**pose, "hfov": 39.0}], 3)  # zooming is moving


def test_the_operator_boxes_the_frame_the_daemon_has() -> None:
    """The daemon applies a selection to the next frame it processes, the camera's latency
    older than the simulator's newest: that frame's record is the one to box."""
    records = [{"t": round(0.04 * f, 2), "frame": f} for f in range(10)]  # 25 fps

    def frame(latency_s: float) -> object:
        record = shown_record(records, latency_s)
        return None if record is None else record["frame"]

    assert frame(0.12) == 6  # 0.24 <= 0.36 - 0.12
    assert frame(0.0) == 9
    assert frame(1.0) == 0  # none that old: the oldest read
    assert shown_record([], 0.12) is None


async def test_the_home_preset_is_stored_on_the_sim_dome_over_its_tcp_serial() -> None:
    """The soak's installer step: real bytes over the sim-camera's real TCP serial, and the
    dome stores its start pose as the home preset the soak's daemon goes to when lost."""
    from ptzd.clock import RealClock
    from ptzd.sim.camera import SimCamera
    from ptzd.sim.config import SimConfig
    from ptzd.sim.dome import PresetPose
    from ptzd.sim.endpoint import TcpEndpoint
    from ptzd.soak import HOME_PRESET, _install_home_preset
    from tests.sim_helpers import ArraySource

    clock = RealClock()
    black = ArraySource([np.zeros((120, 160, 3), np.uint8)])  # the dome's pose is what matters
    camera = SimCamera(black, SimConfig(home_pan=-12.5, home_tilt=4.0), clock)
    endpoint = TcpEndpoint(camera.link, clock, "127.0.0.1", 0)
    host, port = (await endpoint.open()).rsplit(":", 1)
    runner = asyncio.create_task(camera.link.run())
    try:
        assert camera.dome.presets == {}
        await _install_home_preset(host, int(port))
        async with asyncio.timeout(10):
            while HOME_PRESET not in camera.dome.presets:
                await asyncio.sleep(0.01)
                camera.dome.advance_to(clock.now())  # as the camera's render loop does
        assert camera.dome.presets == {HOME_PRESET: PresetPose(-12.5, 4.0, 0.0)}
        assert camera.foreign_frames == 0 and camera.link.parser.bad_checksums == 0
    finally:
        runner.cancel()
        await endpoint.close()
