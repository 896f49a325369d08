"""The simulated dome on the wire: a real pty and real TCP, wire timing, replies, the camera
loop on a virtual clock, the recorder and the MJPEG stream."""

from __future__ import annotations

import asyncio
import json
import os
from pathlib import Path

import cv2
import numpy as np
import pytest
import serial

from ptzd.clock import RealClock, VirtualClock
from ptzd.pelco.codec import (
    Axis,
    Frame,
    Motion,
    PelcoProtocol,
    PositionQuery,
    PositionReply,
    Zoom,
    decode,
    encode,
)
from ptzd.sim.camera import Recorder, SimCamera
from ptzd.sim.config import SimConfig
from ptzd.sim.endpoint import PtyEndpoint, SerialLink, TcpEndpoint
from ptzd.sim.groundtruth import GroundTruth
from ptzd.sim.mjpeg import MjpegServer
from tests.sim_helpers import ArraySource

P, D = PelcoProtocol.P, PelcoProtocol.D


def _wide_frames(n: int = 8, size: tuple[int, int] = (768, 576)) -> list[np.ndarray]:
    rng = np.random.default_rng(11)
    small = rng.integers(0, 256, (size[1] // 16, size[0] // 16, 3), dtype=np.uint8)
    base = cv2.resize(small, size, interpolation=cv2.INTER_LINEAR)
    return [np.roll(base, 3 * i, axis=1) for i in range(n)]


class Received:
    """Frames handed to the dome side, with their arrival times; wakes waiters per frame."""

    def __init__(self, reply: bytes | None = None) -> None:
        self.frames: list[tuple[Frame, float, float]] = []  # frame, arrival, clock at delivery
        self.changed = asyncio.Event()
        self.reply = reply
        self.clock = RealClock()

    def __call__(self, frame: Frame, t: float) -> bytes | None:
        self.frames.append((frame, t, self.clock.now()))
        self.changed.set()
        return self.reply

    async def wait_for(self, count: int) -> None:
        async with asyncio.timeout(30):  # generous: the CI machine is shared
            while len(self.frames) < count:
                self.changed.clear()
                await self.changed.wait()


async def test_pty_frames_garbage_wire_time_and_reopen() -> None:
    received = Received()
    link = SerialLink(received, RealClock(), baudrate=2400)
    endpoint = PtyEndpoint(link, RealClock())
    path = endpoint.open()
    runner = asyncio.create_task(link.run())
    try:
        assert path.startswith("/dev/") and os.isatty(endpoint._slave)
        stop = encode(Motion(), protocol=P, address=1)
        move = encode(Motion(pan=-20, tilt=5), protocol=D, address=1)
        corrupt = bytearray(move)
        corrupt[-1] ^= 0xFF
        payload = stop + b"\x13\x37garbage" + bytes(corrupt) + move
        port = serial.Serial(path, baudrate=2400, timeout=1)
        await asyncio.to_thread(port.write, payload)
        await received.wait_for(2)
        port.close()  # the controller goes away ...
        assert [f.command for f, _, _ in received.frames] == [Motion(), Motion(pan=-20, tilt=5)]
        assert received.frames[0][0].protocol == P and received.frames[1][0].protocol == D
        assert link.bad_frames == 1 == link.parser.bad_checksums  # the corrupted copy
        assert link.parser.garbage_bytes >= len(b"\x13\x37garbage") + len(corrupt)
        # ... the line is timed: the second frame ends len(rest) byte times after the first
        (_, t0, _), (_, t1, delivered) = received.frames
        rest = len(payload) - len(stop)
        assert t1 - t0 == pytest.approx(rest * 10 / 2400, abs=1e-9)
        assert delivered >= t1 - 1e-3  # handed over no earlier than its last byte arrived
        # ... and comes back on the same path
        port = serial.Serial(path, baudrate=2400, timeout=1)
        await asyncio.to_thread(port.write, encode(Motion(zoom=Zoom.IN), protocol=P, address=1))
        await received.wait_for(3)
        port.close()
        assert received.frames[2][0].command == Motion(zoom=Zoom.IN)
    finally:
        runner.cancel()
        endpoint.close()


async def test_tcp_position_query_gets_a_reply_and_clients_can_reconnect() -> None:
    clock = RealClock()
    camera = SimCamera(ArraySource(_wide_frames(2)), SimConfig(home_pan=-12.5), clock)
    endpoint = TcpEndpoint(camera.link, clock, "127.0.0.1", 0)
    address = await endpoint.open()
    host, port = address.rsplit(":", 1)
    runner = asyncio.create_task(camera.link.run())
    try:
        for _ in range(2):
            reader, writer = await asyncio.open_connection(host, int(port))
            writer.write(encode(PositionQuery(Axis.PAN), protocol=D, address=1))
            await writer.drain()
            async with asyncio.timeout(5):
                raw = await reader.readexactly(7)
            reply = decode(raw)
            assert reply.command == PositionReply(Axis.PAN, round(-12.5 * 100) % 36000)
            assert reply.address == 1 and reply.protocol == D
            writer.close()
            await writer.wait_closed()
        # pyserial's socket:// handler, as the daemon's writer uses it
        port_url = serial.serial_for_url(f"socket://{address}", timeout=2)
        await asyncio.to_thread(
            port_url.write, encode(PositionQuery(Axis.TILT), protocol=D, address=1)
        )
        raw = await asyncio.to_thread(port_url.read, 7)
        port_url.close()
        assert decode(raw).command == PositionReply(Axis.TILT, 0)
        # a frame for another dome on the same line is ignored
        assert camera.foreign_frames == 0
    finally:
        runner.cancel()
        await endpoint.close()


async def _scripted_run(directory: Path) -> SimCamera:
    """A camera on a virtual clock with a scripted controller; returns the finished camera."""
    clock = VirtualClock()
    gt = GroundTruth((768, 576), 10.0, {1: {i: (380.0 + i, 280.0, 20.0, 40.0) for i in range(8)}})
    recorder = Recorder(directory)
    recorder.open(ground_truth=True)
    config = SimConfig(baudrate=9600, latency_s=0.03)
    camera = SimCamera(
        ArraySource(_wide_frames(), fps=10.0, ground_truth=gt), config, clock, loop=True,
        recorder=recorder,
    )  # fmt: skip
    script = [
        (0.25, encode(Motion(pan=40, tilt=-20), protocol=P, address=1)),
        (0.90, encode(Motion(zoom=Zoom.IN), protocol=D, address=1)),
        (1.40, b"\x00\xff" + encode(Motion(), protocol=P, address=1)),
        (1.50, encode(Motion(pan=63), protocol=P, address=2)),  # not ours
    ]

    async def controller() -> None:
        for at, data in script:
            await clock.sleep(at - clock.now())
            camera.link.receive(data, clock.now())

    async with asyncio.TaskGroup() as group:
        run = group.create_task(camera.run(duration=2.0))
        group.create_task(controller())
        await clock.run_until(2.0)
        await run
    recorder.close()
    return camera


async def test_virtual_clock_runs_are_repeatable_and_recorded(tmp_path: Path) -> None:
    first = await _scripted_run(tmp_path / "a")
    second = await _scripted_run(tmp_path / "b")
    for name in ("camera", "serial", "groundtruth_view"):
        a = (tmp_path / "a" / f"{name}.jsonl").read_bytes()
        assert a == (tmp_path / "b" / f"{name}.jsonl").read_bytes(), name
    lines = [json.loads(x) for x in (tmp_path / "a" / "camera.jsonl").read_text().splitlines()]
    assert len(lines) == 20 == first.frames_rendered
    assert set(lines[0]) == {"t", "video_frame", "pan", "tilt", "hfov", "width", "height"}
    assert [x["video_frame"] for x in lines[:10]] == [0, 1, 2, 3, 4, 5, 6, 7, 0, 1]  # looped
    assert lines[1]["t"] == pytest.approx(0.1)
    # the pose recorded is the dome's: still until the first command has arrived and acted
    assert lines[2]["pan"] == 0.0 and lines[4]["pan"] > 0.0 and lines[4]["tilt"] < 0.0
    assert lines[-1]["hfov"] < lines[8]["hfov"] == pytest.approx(60.0)
    assert lines[-1]["pan"] == lines[-2]["pan"]  # stopped
    assert first.foreign_frames == 1 == second.foreign_frames
    serial_lines = [
        json.loads(x) for x in (tmp_path / "a" / "serial.jsonl").read_text().splitlines()
    ]
    assert [x["command"] for x in serial_lines] == ["Motion"] * 4
    # arrival = send time + 8 (Pelco-P) byte times at 9600 baud
    assert serial_lines[0]["t"] == pytest.approx(0.25 + 8 * 10 / 9600)
    # view-space ground truth is the model's projection of the wide box
    gt_lines = [
        json.loads(x) for x in (tmp_path / "a" / "groundtruth_view.jsonl").read_text().splitlines()
    ]
    model = first.model
    from ptzd.sim.camera_model import Pose

    for line, cam in zip(gt_lines, lines, strict=True):
        box = model.box_to_view(
            (380.0 + cam["video_frame"], 280.0, 20.0, 40.0),
            Pose(cam["pan"], cam["tilt"], cam["hfov"]),
        )
        got = line["boxes"].get("1")
        assert (got is None) == (box is None)
        if box is not None:
            assert got == pytest.approx(list(box), abs=1e-3)


async def test_in_process_frames_and_mjpeg_stream() -> None:
    clock = RealClock()
    camera = SimCamera(ArraySource(_wide_frames(), fps=20.0), SimConfig(), clock, loop=True)
    server = MjpegServer("127.0.0.1", 0)
    camera.listeners.append(server.publish)
    url = await server.start()
    run = asyncio.create_task(camera.run(duration=3.0))
    try:
        # in-process consumer: frames with increasing capture times and the rendered pose
        seen = []
        async for frame in camera.frames():
            seen.append(frame)
            if len(seen) == 3:
                break
        assert [f.t for f in seen] == sorted(f.t for f in seen)
        assert seen[0].image.shape == (480, 640, 3) and seen[0].pose.hfov == pytest.approx(60.0)

        # raw HTTP: multipart parts carry X-Timestamp
        reader, writer = await asyncio.open_connection(*url.split("/")[2].split(":"))
        writer.write(b"GET /video.mjpg HTTP/1.1\r\nHost: x\r\n\r\n")
        async with asyncio.timeout(5):
            head = await reader.readuntil(b"\r\n\r\n")
            assert b"multipart/x-mixed-replace" in head
            part = await reader.readuntil(b"\r\n\r\n")
        writer.close()
        headers = dict(
            line.split(": ", 1) for line in part.decode().split("\r\n")[1:] if ": " in line
        )
        assert float(headers["X-Timestamp"]) <= clock.now()
        assert int(headers["Content-Length"]) > 1000

        # a separate reader opens it exactly like a cheap IP camera
        def grab() -> tuple[bool, np.ndarray | None]:
            capture = cv2.VideoCapture(url)
            try:
                return capture.read()
            finally:
                capture.release()

        ok, image = await asyncio.to_thread(grab)
        assert ok and image is not None and image.shape == (480, 640, 3)
    finally:
        run.cancel()
        await server.close()


def test_link_rejects_nonsense_baud() -> None:
    with pytest.raises(ValueError, match="baudrate"):
        SerialLink(lambda frame, t: None, RealClock(), baudrate=0)


def test_pty_path_is_a_terminal() -> None:
    async def open_close() -> None:
        endpoint = PtyEndpoint(
            SerialLink(lambda frame, t: None, RealClock(), baudrate=4800), RealClock()
        )
        path = endpoint.open()
        fd = os.open(path, os.O_RDWR | os.O_NOCTTY)
        try:
            assert os.isatty(fd)
        finally:
            os.close(fd)
            endpoint.close()

    asyncio.run(open_close())


async def test_virtual_clock_wakes_sleepers_in_order_at_their_times() -> None:
    clock = VirtualClock(start=5.0)
    woke: list[tuple[str, float]] = []

    async def sleeper(name: str, seconds: float) -> None:
        await clock.sleep(seconds)
        woke.append((name, clock.now()))

    tasks = [asyncio.create_task(sleeper(n, s)) for n, s in (("b", 2.0), ("a", 1.0), ("c", 2.0))]
    await clock.settle()
    assert clock.next_deadline() == 6.0 and not woke
    await clock.run_until(6.5)
    assert woke == [("a", 6.0)] and clock.now() == 6.5
    await clock.run_until(10.0)
    assert woke == [("a", 6.0), ("b", 7.0), ("c", 7.0)]  # ties wake in the order they slept
    await asyncio.gather(*tasks)
    with pytest.raises(ValueError, match="back"):
        clock.advance_to(9.0)


def test_night_mode_renders_grey_views_from_its_time() -> None:
    """A day/night dome at dusk: colour views, then grey ones in three equal channels."""
    from ptzd.vision.auto import colour_share

    clock = VirtualClock()
    config = SimConfig(night_after_s=0.5)
    camera = SimCamera(ArraySource(_wide_frames(), fps=10.0), config, clock, loop=True)
    day_camera = SimCamera(ArraySource(_wide_frames(), fps=10.0), SimConfig(), clock, loop=True)
    before = camera.render(4, camera.epoch + 0.4).image
    after = camera.render(5, camera.epoch + 0.5).image
    assert colour_share(before) > 0.5 and np.array_equal(
        before, day_camera.render(4, day_camera.epoch + 0.4).image
    )
    assert after.shape == before.shape and colour_share(after, step=1) == 0.0
    day = day_camera.render(5, day_camera.epoch + 0.5).image
    luma = cv2.cvtColor(day, cv2.COLOR_BGR2GRAY)
    assert np.array_equal(after[..., 1], luma)
