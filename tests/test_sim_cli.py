"""`ptzd sim render` and `ptzd sim-camera` as a user runs them (real subprocesses)."""

from __future__ import annotations

import contextlib
import json
import socket
import subprocess
import sys
import time
from pathlib import Path

import cv2
import numpy as np
import pytest

from ptzd.sim.camera_model import CameraModel, Pose


def _ptzd(*args: str, timeout: float = 60) -> subprocess.CompletedProcess[str]:
    return subprocess.run(
        [sys.executable, "-m", "ptzd", "--log-format", "json", *args],
        capture_output=True,
        text=True,
        timeout=timeout,
    )


@pytest.fixture
def wide_png(tmp_path: Path) -> Path:
    rng = np.random.default_rng(5)
    small = rng.integers(0, 256, (72, 96, 3), dtype=np.uint8)
    wide = cv2.resize(small, (768, 576), interpolation=cv2.INTER_LINEAR)
    path = tmp_path / "wide.png"
    cv2.imwrite(str(path), wide)
    return path


def test_render_matches_the_model(wide_png: Path, tmp_path: Path) -> None:
    out = tmp_path / "view.png"
    result = _ptzd(
        "sim", "render", "--image", str(wide_png), "--wide-hfov", "90", "--pan", "10.5",
        "--tilt", "-4", "--hfov", "30", "--size", "320x240", "--out", str(out),
    )  # fmt: skip
    assert result.returncode == 0, result.stderr
    view = cv2.imread(str(out))
    assert view is not None and view.shape == (240, 320, 3)
    wide = np.asarray(cv2.imread(str(wide_png)), dtype=np.uint8)
    expected = CameraModel((768, 576), 90.0, (320, 240)).render(wide, Pose(10.5, -4.0, 30.0))
    assert np.array_equal(view, expected)


@pytest.mark.parametrize(
    ("change", "message"),
    [
        ({"--size": "640by480"}, "--size"),
        ({"--hfov": "180"}, "--hfov"),
        ({"--wide-hfov": "0"}, "--wide-hfov"),
        ({"--image": "/nonexistent/wide.png"}, "cannot read image"),
        ({"--out": "/nonexistent/dir/view.png"}, "cannot write"),
    ],
)
def test_render_bad_input_is_one_clear_line(
    wide_png: Path, tmp_path: Path, change: dict[str, str], message: str
) -> None:
    args = {
        "--image": str(wide_png), "--wide-hfov": "90", "--pan": "0", "--tilt": "0",
        "--hfov": "30", "--size": "64x48", "--out": str(tmp_path / "v.png"),
    }  # fmt: skip
    args.update(change)
    result = _ptzd("sim", "render", *[item for pair in args.items() for item in pair])
    assert result.returncode == 2
    assert message in result.stderr
    assert len(result.stderr.strip().splitlines()) == 1


@pytest.fixture(scope="module")
def wide_video(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """A short real video file (MJPG in AVI), decoded by the simulator like vtest.avi."""
    path = tmp_path_factory.mktemp("video") / "wide.avi"
    writer = cv2.VideoWriter(str(path), cv2.VideoWriter.fourcc(*"MJPG"), 10.0, (384, 288))
    assert writer.isOpened()
    rng = np.random.default_rng(2)
    small = rng.integers(0, 256, (18, 24, 3), dtype=np.uint8)
    base = cv2.resize(small, (384, 288), interpolation=cv2.INTER_LINEAR)
    for i in range(15):
        writer.write(np.roll(base, 4 * i, axis=1))
    writer.release()
    return path


def _jsonl(path: Path) -> list[dict[str, object]]:
    return [json.loads(line) for line in path.read_text().splitlines()]


def test_sim_camera_virtual_clock_replay_is_bit_for_bit(wide_video: Path, tmp_path: Path) -> None:
    from ptzd.pelco.codec import Motion, PelcoProtocol, Zoom, encode

    script = tmp_path / "script.jsonl"
    commands = [
        (0.3, encode(Motion(pan=-30, tilt=10), protocol=PelcoProtocol.P, address=1)),
        (0.8, encode(Motion(zoom=Zoom.IN), protocol=PelcoProtocol.D, address=1)),
        (1.2, encode(Motion(), protocol=PelcoProtocol.P, address=1)),
    ]
    script.write_text("".join(json.dumps({"t": t, "hex": b.hex(" ")}) + "\n" for t, b in commands))
    outputs = []
    for name in ("a", "b"):
        result = _ptzd(
            "sim-camera", "--video", str(wide_video), "--loop", "--wide-hfov", "70",
            "--serial", "tcp://127.0.0.1:0", "--virtual-clock", "--duration", "2",
            "--replay", str(script), "--record", str(tmp_path / name),
        )  # fmt: skip
        assert result.returncode == 0, result.stderr
        assert result.stdout.startswith("serial socket://127.0.0.1:")
        outputs.append((tmp_path / name / "camera.jsonl").read_bytes())
    assert outputs[0] == outputs[1]
    camera = _jsonl(tmp_path / "a" / "camera.jsonl")
    assert len(camera) == 20
    assert [c["video_frame"] for c in camera[13:17]] == [13, 14, 0, 1]  # 15 frames, looped
    assert camera[2]["pan"] == 0.0 and float(camera[9]["pan"]) < 0.0  # type: ignore[arg-type]
    assert camera[-1]["pan"] == camera[-2]["pan"]
    serial_log = _jsonl(tmp_path / "a" / "serial.jsonl")
    assert [s["command"] for s in serial_log] == ["Motion"] * 3
    assert [round(float(s["t"]), 6) for s in serial_log] == [0.3, 0.8, 1.2]  # type: ignore[arg-type]
    # replaying the recorded serial log reproduces the run exactly
    again = _ptzd(
        "sim-camera", "--video", str(wide_video), "--loop", "--wide-hfov", "70",
        "--serial", "tcp://127.0.0.1:0", "--virtual-clock", "--duration", "2",
        "--replay", str(tmp_path / "a" / "serial.jsonl"), "--record", str(tmp_path / "c"),
    )  # fmt: skip
    assert again.returncode == 0, again.stderr
    assert (tmp_path / "c" / "camera.jsonl").read_bytes() == outputs[0]


def test_sim_camera_real_time_over_a_pty(wide_video: Path, tmp_path: Path) -> None:
    import serial

    from ptzd.pelco.codec import Motion, PelcoProtocol, encode

    process = subprocess.Popen(
        [sys.executable, "-m", "ptzd", "--log-format", "json", "sim-camera", "--video",
         str(wide_video), "--loop", "--duration", "2.5", "--record", str(tmp_path)],
        stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True,
    )  # fmt: skip
    try:
        assert process.stdout is not None
        first = process.stdout.readline().split()
        assert first[0] == "serial" and first[1].startswith("/dev/")
        with serial.Serial(first[1], baudrate=4800, timeout=1) as port:
            port.write(encode(Motion(pan=63), protocol=PelcoProtocol.P, address=1))
        out, err = process.communicate(timeout=30)
    finally:
        process.kill()
    assert process.returncode == 0, err
    summary = json.loads(out.strip().splitlines()[-1])
    assert summary["serial_frames"] == 1
    camera = _jsonl(tmp_path / "camera.jsonl")
    assert len(camera) >= 20
    assert float(camera[-1]["pan"]) > 30.0  # type: ignore[arg-type]
    assert _jsonl(tmp_path / "serial.jsonl")[0]["pan"] == 63


@pytest.mark.parametrize(
    ("args", "message"),
    [
        (["--video", "/nonexistent.avi", "--duration", "1"], "no such file"),
        (["--serial", "tcp://nohost", "--duration", "1"], "--serial"),
        (["--virtual-clock"], "--duration"),
        (["--duration", "-1"], "--duration"),
        (["--config", "BAD_CONFIG", "--duration", "1"], "tilt_min"),
        (["--gt", "BAD_GT", "--duration", "1"], "ground truth"),
    ],
)
def test_sim_camera_bad_input(
    wide_video: Path, tmp_path: Path, args: list[str], message: str
) -> None:
    bad_config = tmp_path / "bad.toml"
    bad_config.write_text("[sim]\ntilt_min = 10.0\ntilt_max = 0.0\n")
    bad_gt = tmp_path / "gt.json"
    bad_gt.write_text(json.dumps({"size": [640, 480], "fps": 10, "tracks": []}))
    args = [
        str(bad_config) if a == "BAD_CONFIG" else str(bad_gt) if a == "BAD_GT" else a for a in args
    ]
    if "--video" not in args:
        args = ["--video", str(wide_video), *args]
    result = _ptzd("sim-camera", *args)
    assert result.returncode == 2, result.stderr
    assert message in result.stderr


def _open_mjpeg(url: str) -> socket.socket:
    """A raw HTTP connection to the sim-camera's MJPEG stream at `url`, request sent."""
    host, port = url.split("/")[2].split(":")
    stream = socket.create_connection((host, int(port)), timeout=5)
    stream.sendall(b"GET /video.mjpg HTTP/1.1\r\nHost: x\r\n\r\n")
    return stream


def _received_within(stream: socket.socket, seconds: float) -> bytes:
    """Whatever the stream delivers in the next `seconds`."""
    stream.settimeout(0.1)
    data = b""
    end = time.monotonic() + seconds
    while time.monotonic() < end:
        with contextlib.suppress(TimeoutError):
            data += stream.recv(65536)
    return data


def test_sim_camera_stream_stalls_on_sigusr1_while_the_dome_takes_commands(
    wide_video: Path, tmp_path: Path
) -> None:
    """The soak's `stream-stall`: SIGUSR1 stops the MJPEG parts, the dome still obeys the
    serial line (a STOP sent during the stall stops it then, not on resume), SIGUSR2 resumes."""
    import itertools
    import signal

    import serial

    from ptzd.pelco.codec import Motion, PelcoProtocol, encode

    process = subprocess.Popen(
        [sys.executable, "-m", "ptzd", "--log-format", "json", "sim-camera", "--video",
         str(wide_video), "--loop", "--duration", "6", "--http", "127.0.0.1:0",
         "--record", str(tmp_path)],
        stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True,
    )  # fmt: skip
    try:
        assert process.stdout is not None
        pty_path = process.stdout.readline().split()[1]
        stream = _open_mjpeg(process.stdout.readline().split()[1])

        def parts_within(seconds: float) -> int:
            return _received_within(stream, seconds).count(b"X-Frame:")

        assert parts_within(0.5) > 2
        with serial.Serial(pty_path, baudrate=4800, timeout=1) as line:
            line.write(encode(Motion(pan=63), protocol=PelcoProtocol.P, address=1))
            process.send_signal(signal.SIGUSR1)
            parts_within(0.2)  # what was in flight
            line.write(encode(Motion(), protocol=PelcoProtocol.P, address=1))
            assert parts_within(1.0) == 0
            process.send_signal(signal.SIGUSR2)
            assert parts_within(0.5) > 2
        stream.close()
        _, err = process.communicate(timeout=30)
    finally:
        process.kill()
    assert process.returncode == 0, err
    camera = _jsonl(tmp_path / "camera.jsonl")
    serial_log = _jsonl(tmp_path / "serial.jsonl")
    assert [s["pan"] for s in serial_log] == [63, 0]
    # the dome went on through the stall (no gap in what it rendered), took the STOP when it
    # was sent, and stood still from then on
    times = [float(c["t"]) for c in camera]  # type: ignore[arg-type]
    assert max(b - a for a, b in itertools.pairwise(times)) < 0.2
    stop_t = float(serial_log[1]["t"])  # type: ignore[arg-type]
    after = [c for c in camera if float(c["t"]) > stop_t + 0.3]  # type: ignore[arg-type]
    assert after and len({c["pan"] for c in after}) == 1
    assert float(after[0]["pan"]) > 0.0  # type: ignore[arg-type]


def test_sim_camera_goes_to_night_mode_on_the_dusk_signal(wide_video: Path) -> None:
    """The soak's `day-night`: DUSK_SIGNAL turns the MJPEG views grey, DAWN_SIGNAL back."""

    from ptzd.sim.cli import DAWN_SIGNAL, DUSK_SIGNAL
    from ptzd.vision.auto import colour_share

    process = subprocess.Popen(
        [sys.executable, "-m", "ptzd", "--log-format", "json", "sim-camera", "--video",
         str(wide_video), "--loop", "--duration", "6", "--http", "127.0.0.1:0"],
        stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True,
    )  # fmt: skip
    try:
        assert process.stdout is not None
        process.stdout.readline()  # the serial port
        stream = _open_mjpeg(process.stdout.readline().split()[1])

        def newest_share(after_s: float) -> float:
            """The colour share of the last whole JPEG part received within `after_s`."""
            data = _received_within(stream, after_s)
            last_end = data.rindex(b"\xff\xd9") + 2
            start = data.rindex(b"\xff\xd8", 0, last_end)
            image = cv2.imdecode(np.frombuffer(data[start:last_end], np.uint8), cv2.IMREAD_COLOR)
            return colour_share(np.asarray(image, np.uint8))

        assert newest_share(0.5) > 0.5
        process.send_signal(DUSK_SIGNAL)
        assert newest_share(0.5) == 0.0
        process.send_signal(DAWN_SIGNAL)
        assert newest_share(0.5) > 0.5
        stream.close()
        _, err = process.communicate(timeout=30)
    finally:
        process.kill()
    assert process.returncode == 0, err
