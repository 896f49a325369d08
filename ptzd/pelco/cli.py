"""`ptzd pelco encode|decode|send|demo`: the codec and the link from the command line.

The encode/decode forms are an external contract (shared/interfaces.md): lowercase hex bytes
separated by spaces; one JSON object per decoded frame, one per line.
"""

from __future__ import annotations

import argparse
import json
import string
from typing import Any

from ptzd.errors import UsageError


def register(subparsers: argparse._SubParsersAction[Any]) -> None:
    pelco = subparsers.add_parser("pelco", help="encode, decode and send Pelco-P/D frames")
    commands = pelco.add_subparsers(dest="pelco_command", metavar="ACTION")
    commands.required = True

    encode = commands.add_parser("encode", help="print the frame for one command as hex")
    _command_arguments(encode)
    encode.set_defaults(handler=_encode)

    decode = commands.add_parser("decode", help="decode hex (garbage allowed) to JSON lines")
    decode.add_argument("hex", nargs="+", metavar="HEX", help="hex bytes, any spacing")
    decode.set_defaults(handler=_decode)

    send = commands.add_parser("send", help="send one command to a port, then STOP")
    send.add_argument("--port", required=True, help="pyserial URL: /dev/ttyUSB0, socket://h:p")
    send.add_argument("--baudrate", type=int, default=None, help="default: P 4800, D 2400")
    send.add_argument(
        "--for", dest="duration", type=float, default=1.0, help="seconds before STOP (1)"
    )
    _command_arguments(send)
    send.set_defaults(handler=_send)

    demo = commands.add_parser("demo", help="drive a pty with a scripted motion sequence")
    demo.add_argument("--seconds", type=float, default=5.0, help="length of the demo (5)")
    demo.set_defaults(handler=_demo)


def _command_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("--protocol", choices=["p", "d"], required=True)
    parser.add_argument("--address", type=int, required=True, help="the dome's own address")
    parser.add_argument("--pan", type=int, default=0, help="< 0 left, |S| 0..63, 64 = turbo")
    parser.add_argument("--tilt", type=int, default=0, help="> 0 up, |S| 0..63")
    parser.add_argument("--zoom", choices=["in", "out"], default=None)
    parser.add_argument("--focus", choices=["near", "far"], default=None)
    parser.add_argument("--iris", choices=["open", "close"], default=None)
    parser.add_argument(
        "--preset", nargs=2, metavar=("{set,clear,goto}", "NUM"), default=None, help="preset"
    )
    parser.add_argument("--zoom-speed", type=int, default=None, metavar="0..3")


def build_command(args: argparse.Namespace) -> Any:
    """The codec command the arguments describe; `UsageError` for bad or mixed arguments."""
    from ptzd.pelco.codec import CommandValueError, Motion, Preset, PresetAction, Zoom, ZoomSpeed

    moving = args.pan or args.tilt or args.zoom or args.focus or args.iris
    try:
        if args.preset is not None:
            if moving or args.zoom_speed is not None:
                raise UsageError("--preset cannot be combined with motion or --zoom-speed")
            action, number = args.preset
            if action not in ("set", "clear", "goto"):
                raise UsageError(f"--preset action must be set, clear or goto, got {action!r}")
            try:
                value = int(number)
            except ValueError:
                raise UsageError(f"--preset number must be an integer, got {number!r}") from None
            return Preset(PresetAction(action), value)
        if args.zoom_speed is not None:
            if moving:
                raise UsageError("--zoom-speed cannot be combined with motion")
            return ZoomSpeed(args.zoom_speed)
        return Motion(
            pan=args.pan,
            tilt=args.tilt,
            zoom={"in": Zoom.IN, "out": Zoom.OUT, None: Zoom.NONE}[args.zoom],
            focus={"near": -1, "far": 1, None: 0}[args.focus],
            iris={"close": -1, "open": 1, None: 0}[args.iris],
        )
    except CommandValueError as exc:
        raise UsageError(str(exc)) from None


def _encode(args: argparse.Namespace) -> int:
    from ptzd.pelco.codec import CommandValueError, PelcoProtocol, encode

    command = build_command(args)
    try:
        frame = encode(command, protocol=PelcoProtocol(args.protocol), address=args.address)
    except CommandValueError as exc:
        raise UsageError(str(exc)) from None
    print(frame.hex(" "))
    return 0


def parse_hex(words: list[str]) -> bytes:
    """Bytes from hex words: `a0 00 af`, `a000af`, `0xa0,0x00`; `UsageError` otherwise."""
    text = " ".join(words).lower().replace("0x", " ")
    for sep in ",:;-":
        text = text.replace(sep, " ")
    digits = "".join(text.split())
    bad = [c for c in digits if c not in string.hexdigits]
    if bad:
        raise UsageError(f"not hex: {bad[0]!r}")
    if len(digits) % 2:
        raise UsageError(f"odd number of hex digits ({len(digits)})")
    return bytes.fromhex(digits)


def _decode(args: argparse.Namespace) -> int:
    from ptzd.pelco.codec import FrameParser, frame_to_dict

    parser = FrameParser()
    for frame in parser.feed(parse_hex(args.hex)):
        print(json.dumps(frame_to_dict(frame)))
    return 0


def _send(args: argparse.Namespace) -> int:
    import asyncio

    from ptzd.pelco.codec import CommandValueError, Motion, PelcoProtocol, encode
    from ptzd.pelco.config import SerialConfig
    from ptzd.pelco.link import LinkError, PelcoLink

    command = build_command(args)
    try:
        encode(command, protocol=PelcoProtocol(args.protocol), address=args.address)
    except CommandValueError as exc:
        raise UsageError(str(exc)) from None
    if not 0.0 <= args.duration <= 3600.0:
        raise UsageError(f"--for must be 0..3600 seconds, got {args.duration}")
    try:
        config = SerialConfig(
            port=args.port, protocol=args.protocol, address=args.address, baudrate=args.baudrate
        )
    except ValueError as exc:
        raise UsageError(str(exc).splitlines()[0]) from None

    async def run() -> None:
        async with PelcoLink(config) as link:
            loop = asyncio.get_running_loop()
            end = loop.time() + args.duration
            link.send(command)
            while (left := end - loop.time()) > 0:
                # refresh well inside the dead-man timeout so a long --for keeps moving
                await asyncio.sleep(min(left, config.deadman_s / 3))
                if isinstance(command, Motion):
                    link.send(command)
            print(json.dumps({"port": args.port, **vars(link.counters)}))

    try:
        asyncio.run(run())
    except LinkError as exc:
        raise UsageError(str(exc)) from None
    return 0


def _demo(args: argparse.Namespace) -> int:
    from ptzd.pelco.demo import run_demo

    if not 0.5 <= args.seconds <= 600.0:
        raise UsageError(f"--seconds must be 0.5..600, got {args.seconds}")
    return run_demo(args.seconds)
