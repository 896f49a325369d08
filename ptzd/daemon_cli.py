"""`ptzd run --config FILE [--init X,Y,W,H] [--validate-config]`: the daemon."""

from __future__ import annotations

import argparse
import math
from typing import TYPE_CHECKING, Any

from ptzd.errors import UsageError

if TYPE_CHECKING:
    from ptzd.config import Config


def register(subparsers: argparse._SubParsersAction[Any]) -> None:
    parser = subparsers.add_parser(
        "run",
        help="run the tracking daemon",
        description="Capture from [capture].source, track the selected target and drive the "
        "dome on [serial].port. SIGINT/SIGTERM stop it in order; the dome is left stopped.",
    )
    parser.add_argument("--config", required=True, help="TOML config file")
    parser.add_argument(
        "--init", metavar="X,Y,W,H", help="initial target box in the first frame (pixels)"
    )
    parser.add_argument(
        "--validate-config",
        action="store_true",
        help="only validate the config (errors name the key; exit 2), then exit 0",
    )
    parser.set_defaults(handler=_run)


def parse_box(text: str, option: str = "--init") -> tuple[float, float, float, float]:
    """`X,Y,W,H` -> a finite box with positive size, or `UsageError`."""
    parts = text.split(",")
    try:
        values = [float(p) for p in parts]
    except ValueError:
        values = []
    if len(values) != 4 or not all(math.isfinite(v) for v in values):
        raise UsageError(f"{option} must be X,Y,W,H (four numbers); got {text!r}")
    x, y, w, h = values
    if w <= 0 or h <= 0:
        raise UsageError(f"{option} needs a positive width and height; got {text!r}")
    return x, y, w, h


def configure_logging_from(config: Config, args: argparse.Namespace) -> None:
    """Logging as the config says (`[logging]`, `[camera].name` on every line), once it is
    read; the CLI's `--log-level`/`--log-format` still win."""
    from ptzd.logs import configure_logging

    configure_logging(
        level=getattr(args, "log_level", None) or config.logging.level,
        fmt=getattr(args, "log_format", None) or config.logging.format,
        camera=config.camera.name,
    )


def _run(args: argparse.Namespace) -> int:
    from ptzd.config import load_config

    config = load_config(args.config)  # ConfigError -> one line per key, exit 2
    init = parse_box(args.init) if args.init else None
    if args.validate_config:
        print(f"{args.config}: ok")
        return 0
    configure_logging_from(config, args)
    if config.capture.source == "sim":
        from ptzd.closed_loop import run_sim_capture

        return run_sim_capture(config, init)
    import asyncio

    return asyncio.run(run_daemon(config, init))


async def run_daemon(config: Config, init: tuple[float, float, float, float] | None) -> int:
    """The daemon on real hardware: cv2 capture, PelcoLink, signals for shutdown, and
    sd_notify when systemd started it (`$NOTIFY_SOCKET`, `$WATCHDOG_USEC`)."""
    import asyncio
    import signal

    from ptzd.app import Daemon, daemon_detector
    from ptzd.capture import VideoCaptureSource
    from ptzd.clock import RealClock
    from ptzd.mqtt.bridge import optional_bridge
    from ptzd.pelco.link import PelcoLink
    from ptzd.sdnotify import Notifier
    from ptzd.vision.tracking import make_tracker

    clock = RealClock()
    detector = daemon_detector(config)  # before anything opens: a bad codebook exits 2
    notifier = Notifier.from_environ()
    source = VideoCaptureSource(config.capture.source, clock, latency_s=config.capture.latency_s)
    loop = asyncio.get_running_loop()
    async with (
        PelcoLink(config.serial, clock=clock) as link,
        optional_bridge(config.mqtt, config.camera.name, clock=clock) as bridge,
    ):
        daemon = Daemon(
            config,
            source=source,
            tracker_factory=lambda: make_tracker(config.tracker),
            link=link,
            clock=clock,
            initial_box=init,
            bridge=bridge,
            detector=detector,
            notifier=notifier,
        )
        for sig in (signal.SIGINT, signal.SIGTERM):
            loop.add_signal_handler(sig, daemon.request_stop)
        # no config reload: SIGHUP (kill -HUP, a hung-up terminal) must not kill the daemon
        # with the dome moving, so it is logged and ignored
        loop.add_signal_handler(signal.SIGHUP, _log_sighup)
        try:
            await daemon.run()
        finally:
            for sig in (signal.SIGINT, signal.SIGTERM, signal.SIGHUP):
                loop.remove_signal_handler(sig)
            notifier.close()
    return 0


def _log_sighup() -> None:
    from ptzd.logs import get_logger

    get_logger("daemon").warning("sighup_ignored", reason="config reload is not supported")
