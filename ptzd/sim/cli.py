"""Command-line entry points of `ptzd.sim`: `sim render` and `sim-camera`.

`sim` is a parser whose `render` subcommand is optional: `ptzd sim` without a subcommand is
the closed loop (simulated dome + daemon), added with its own options on the same parser.
"""

from __future__ import annotations

import argparse
import asyncio
import json
import re
import signal
from pathlib import Path
from typing import TYPE_CHECKING, Any

from ptzd.errors import UsageError

if TYPE_CHECKING:
    from ptzd.sim.camera import SimCamera
    from ptzd.sim.config import SimConfig
    from ptzd.sim.mjpeg import MjpegServer

_SIZE = re.compile(r"^(\d+)x(\d+)$")
_HOST_PORT = re.compile(r"^(?:tcp://)?(\[[^\]]+\]|[^:]*):(\d+)$")


def register(subparsers: argparse._SubParsersAction[Any]) -> None:
    """Add `sim` (with the optional `render` subcommand) and `sim-camera`."""
    sim = subparsers.add_parser("sim", help="simulated dome: render views, run the closed loop")
    from ptzd import closed_loop  # the closed loop's options and handler (light imports only)

    closed_loop.add_arguments(sim)
    sim.set_defaults(handler=closed_loop.handle)
    sim_commands = sim.add_subparsers(
        dest="sim_command", metavar="SUBCOMMAND", parser_class=type(sim), required=False
    )
    render = sim_commands.add_parser("render", help="render one PTZ view of a wide image")
    render.add_argument("--image", required=True, help="wide image (any format cv2 reads)")
    render.add_argument("--wide-hfov", type=float, required=True, help="its horizontal FOV, deg")
    render.add_argument("--pan", type=float, required=True, help="degrees, + right")
    render.add_argument("--tilt", type=float, required=True, help="degrees, + up")
    render.add_argument("--hfov", type=float, required=True, help="view horizontal FOV, deg")
    render.add_argument("--size", required=True, help="view size WxH, e.g. 640x480")
    render.add_argument("--out", required=True, help="output image path (format from extension)")
    render.set_defaults(handler=_render)

    camera = subparsers.add_parser(
        "sim-camera", help="run the simulated dome standalone (pty or TCP serial, MJPEG over HTTP)"
    )
    source = camera.add_mutually_exclusive_group()
    source.add_argument("--video", help="wide video file")
    source.add_argument(
        "--scene", help="procedural wide scene, synthetic[:SEED] (the default: synthetic:0)"
    )
    camera.add_argument("--loop", action="store_true", help="play the video in a loop")
    camera.add_argument("--gt", metavar="GT_JSON", help="ground truth of the video (wide pixels)")
    camera.add_argument("--config", help="TOML config file (its [sim] section is used)")
    camera.add_argument("--wide-hfov", type=float, help="override sim.wide_hfov")
    camera.add_argument(
        "--serial",
        default="pty",
        help="pty (prints the pty path) or tcp://HOST:PORT for socket:// clients (port 0: any)",
    )
    camera.add_argument(
        "--http", metavar="HOST:PORT", help="serve MJPEG at http://HOST:PORT/video.mjpg"
    )
    camera.add_argument("--record", metavar="DIR", help="write camera/serial/ground-truth jsonl")
    camera.add_argument("--duration", type=float, help="stop after S seconds (default: run on)")
    camera.add_argument(
        "--virtual-clock", action="store_true", help="run on a virtual clock, as fast as possible"
    )
    camera.add_argument(
        "--replay", metavar="SERIAL_JSONL", help="feed the bytes of a recorded serial.jsonl"
    )
    camera.set_defaults(handler=_sim_camera)


def parse_size(text: str) -> tuple[int, int]:
    match = _SIZE.match(text.strip())
    if not match or int(match[1]) < 1 or int(match[2]) < 1:
        raise UsageError(f"--size must be WxH with positive integers, e.g. 640x480; got {text!r}")
    return int(match[1]), int(match[2])


def parse_host_port(text: str, option: str) -> tuple[str, int]:
    match = _HOST_PORT.match(text.strip())
    if not match or int(match[2]) > 65535:
        raise UsageError(f"{option} must be HOST:PORT (port 0..65535); got {text!r}")
    return match[1].strip("[]") or "127.0.0.1", int(match[2])


def _render(args: argparse.Namespace) -> int:
    import cv2

    from ptzd.sim.camera_model import CameraModel, Pose

    size = parse_size(args.size)
    for name in ("wide_hfov", "hfov"):
        value = getattr(args, name)
        if not 0.0 < value < 180.0:
            raise UsageError(f"--{name.replace('_', '-')} must be in (0, 180) degrees; got {value}")
    import numpy as np

    try:
        data = Path(args.image).read_bytes()
    except OSError as exc:
        raise UsageError(f"cannot read image {args.image!r}: {exc.strerror}") from None
    wide = cv2.imdecode(np.frombuffer(data, np.uint8), cv2.IMREAD_UNCHANGED)
    if wide is None:
        raise UsageError(f"cannot read image {args.image!r}: not an image format cv2 decodes")
    if wide.dtype != "uint8":
        raise UsageError(f"{args.image}: only 8-bit images are supported, got {wide.dtype}")
    height, width = wide.shape[:2]
    model = CameraModel((width, height), args.wide_hfov, size)
    view = model.render(np.asarray(wide, dtype=np.uint8), Pose(args.pan, args.tilt, args.hfov))
    try:
        written = cv2.imwrite(args.out, view)
    except cv2.error as exc:
        raise UsageError(f"cannot write {args.out!r}: {exc}") from None
    if not written:
        raise UsageError(f"cannot write {args.out!r} (unknown extension or unwritable path)")
    return 0


def _sim_config(args: argparse.Namespace) -> SimConfig:
    from ptzd.config import Config, load_config, validate_config
    from ptzd.errors import ConfigError

    config: Config = load_config(args.config) if args.config else validate_config({})
    sim = config.sim
    if args.wide_hfov is not None:
        try:
            sim = type(sim).model_validate({**sim.model_dump(), "wide_hfov": args.wide_hfov})
        except ValueError as exc:
            raise ConfigError(
                "--wide-hfov", [("sim.wide_hfov", str(exc), args.wide_hfov)]
            ) from None
    return sim


def _sim_camera(args: argparse.Namespace) -> int:
    from ptzd.sim.sources import open_wide_source

    config = _sim_config(args)
    spec = args.video if args.video else (args.scene or "synthetic:0")
    if args.duration is not None and args.duration <= 0:
        raise UsageError(f"--duration must be positive; got {args.duration}")
    if args.virtual_clock and args.duration is None:
        raise UsageError("--virtual-clock needs --duration (it runs as fast as it can)")
    serial = args.serial.strip()
    tcp = None if serial == "pty" else parse_host_port(serial, "--serial")
    http = parse_host_port(args.http, "--http") if args.http else None
    replay = _read_replay(Path(args.replay)) if args.replay else []
    source = open_wide_source(spec, loop=args.loop, gt_path=args.gt)  # UsageError on bad input
    return asyncio.run(
        _run_camera(
            source,
            config,
            loop=args.loop,
            tcp=tcp,
            http=http,
            record=args.record,
            duration=args.duration,
            virtual=args.virtual_clock,
            replay=replay,
        )
    )


def _read_replay(path: Path) -> list[tuple[float, bytes]]:
    """(arrival time, frame bytes) of every line of a recorded serial.jsonl."""
    out: list[tuple[float, bytes]] = []
    try:
        lines = path.read_text(encoding="utf-8").splitlines()
    except OSError as exc:
        raise UsageError(f"cannot read --replay {str(path)!r}: {exc.strerror}") from None
    for number, line in enumerate(lines, 1):
        if not line.strip():
            continue
        try:
            record = json.loads(line)
            out.append((float(record["t"]), bytes.fromhex(record["hex"])))
        except (ValueError, KeyError, TypeError) as exc:
            raise UsageError(f"{path}:{number}: not a serial.jsonl record ({exc})") from None
    return out


async def _run_camera(
    source: Any,
    config: SimConfig,
    *,
    loop: bool,
    tcp: tuple[str, int] | None,
    http: tuple[str, int] | None,
    record: str | None,
    duration: float | None,
    virtual: bool,
    replay: list[tuple[float, bytes]],
) -> int:
    from ptzd.clock import Clock, RealClock, VirtualClock
    from ptzd.sim.camera import Recorder, SimCamera
    from ptzd.sim.endpoint import PtyEndpoint, TcpEndpoint
    from ptzd.sim.mjpeg import MjpegServer

    clock: Clock = VirtualClock() if virtual else RealClock()
    recorder = Recorder(record) if record else None
    if recorder is not None:
        recorder.open(ground_truth=source.ground_truth is not None)
    camera = SimCamera(source, config, clock, loop=loop, recorder=recorder)
    pty_endpoint: PtyEndpoint | None = None
    tcp_endpoint: TcpEndpoint | None = None
    mjpeg: MjpegServer | None = None
    try:
        if tcp is None:
            pty_endpoint = PtyEndpoint(camera.link, clock)
            print(f"serial {pty_endpoint.open()}", flush=True)
        else:
            tcp_endpoint = TcpEndpoint(camera.link, clock, *tcp)
            print(f"serial socket://{await tcp_endpoint.open()}", flush=True)
        if http is not None:
            mjpeg = MjpegServer(*http, quality=config.jpeg_quality)
            camera.listeners.append(mjpeg.publish)
            print(f"http {await mjpeg.start()}", flush=True)
            _stall_on_signals(mjpeg)
        _night_on_signals(camera)
        await _drive(camera, clock, duration, replay)
    finally:
        if pty_endpoint is not None:
            pty_endpoint.close()
        if tcp_endpoint is not None:
            await tcp_endpoint.close()
        if mjpeg is not None:
            await mjpeg.close()
        if recorder is not None:
            recorder.close()
    counters = camera.link.counters
    print(
        json.dumps(
            {
                "frames": camera.frames_rendered,
                "skipped": camera.frames_skipped,
                "serial_frames": counters.frames,
                "bad_checksums": camera.link.parser.bad_checksums,
                "garbage_bytes": camera.link.parser.garbage_bytes,
                "foreign_frames": camera.foreign_frames,
            }
        ),
        flush=True,
    )
    return 0


def _stall_on_signals(mjpeg: MjpegServer) -> None:
    """SIGUSR1 stalls the MJPEG stream, SIGUSR2 resumes it (the soak's `stream-stall`): the
    encoder stops while the dome's controller goes on taking commands, as on a real dome
    whose video stalls. (Freezing the whole process, as the soak once did, also froze the
    dome's serial line and then applied 6 s of the last speed at once on resume.)"""
    loop = asyncio.get_running_loop()
    loop.add_signal_handler(signal.SIGUSR1, mjpeg.stall, True)
    loop.add_signal_handler(signal.SIGUSR2, mjpeg.stall, False)


# the soak's `day-night`: real-time signals, the user ones being the stream's
DUSK_SIGNAL = signal.SIGRTMIN
DAWN_SIGNAL = signal.SIGRTMIN + 1


def _night_on_signals(camera: SimCamera) -> None:
    """DUSK_SIGNAL puts the dome in night mode (grey views, as with its IR-cut filter out),
    DAWN_SIGNAL back in day mode."""
    loop = asyncio.get_running_loop()
    loop.add_signal_handler(DUSK_SIGNAL, setattr, camera, "night", True)
    loop.add_signal_handler(DAWN_SIGNAL, setattr, camera, "night", False)


async def _drive(
    camera: SimCamera, clock: Any, duration: float | None, replay: list[tuple[float, bytes]]
) -> None:
    """Run the camera (and the replayed bytes) to the end, on whichever clock it has."""
    from ptzd.clock import VirtualClock

    async def feed() -> None:
        start = camera.epoch
        for arrival, data in replay:
            # a recorded time is when the last byte arrived: start sending one frame-time before
            # and pin the last byte to the recorded time, so a replay reproduces the run exactly
            send_at = start + arrival - len(data) * camera.link.byte_time
            delay = send_at - clock.now()
            if delay > 0:
                await clock.sleep(delay)
            camera.link.receive(data, clock.now(), ends_at=max(start + arrival, clock.now()))

    async with asyncio.TaskGroup() as group:
        run = group.create_task(camera.run(duration))
        feeder = group.create_task(feed())
        if isinstance(clock, VirtualClock):
            assert duration is not None
            await clock.run_until(camera.epoch + duration)
            await run
            feeder.cancel()
        else:
            await run
            feeder.cancel()
