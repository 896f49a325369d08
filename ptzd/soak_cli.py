"""`ptzd soak --minutes N --report DIR [--virtual-clock] [--faults LIST]`."""

from __future__ import annotations

import argparse
from pathlib import Path
from typing import Any

# the names ptzd.soak.FAULTS accepts (repeated here so `ptzd --help` stays import-light)
FAULT_NAMES = "serial-reset, stream-stall, broker-restart"


def register(subparsers: argparse._SubParsersAction[Any]) -> None:
    parser = subparsers.add_parser(
        "soak",
        help="run daemon, simulated dome and broker for a long time; report leaks and faults",
        description="Start sim-camera, mosquitto and `ptzd run` as separate processes, "
        "inject faults, sample RSS/fds/tasks/loop lag/command rate/MQTT messages and write "
        "DIR/report.json and DIR/soak.png. Exit 0 only if every check passed.",
    )
    parser.add_argument("--minutes", type=float, required=True, help="run time (simulated "
                        "minutes with --virtual-clock)")  # fmt: skip
    parser.add_argument("--report", required=True, metavar="DIR", help="report directory")
    parser.add_argument("--virtual-clock", action="store_true",
                        help="closed loop on the virtual clock, as fast as possible")  # fmt: skip
    parser.add_argument(
        "--faults", default="", metavar="LIST", help="comma-separated, from: " + FAULT_NAMES
    )
    parser.add_argument("--sample-s", type=float, default=2.0, help="sampling period (s)")
    parser.add_argument("--warmup-s", type=float, default=30.0,
                        help="RSS growth is measured from the first sample after this")  # fmt: skip
    parser.add_argument("--max-heap-growth-mb", type=float, default=5.0, metavar="MB",
                        help="the leak check: growth of anonymous RSS after warm-up "
                        "below this (default 5)")  # fmt: skip
    parser.add_argument("--fps", type=float, default=None, metavar="FPS",
                        help="with --virtual-clock: the simulated dome's frame rate "
                        "([sim] fps; default: the scene's 25)")  # fmt: skip
    parser.set_defaults(handler=_soak)


def _soak(args: argparse.Namespace) -> int:
    from ptzd.soak import SoakOptions, run_soak

    faults = tuple(f.strip() for f in args.faults.split(",") if f.strip())
    options = SoakOptions(
        minutes=args.minutes,
        report_dir=Path(args.report),
        faults=faults,
        virtual_clock=args.virtual_clock,
        sample_s=args.sample_s,
        warmup_s=args.warmup_s,
        fps=args.fps,
        max_heap_growth_mb=args.max_heap_growth_mb,
    )
    report = run_soak(options)
    import json

    print(json.dumps({"ok": report["ok"], **report["summary"]}))
    return 0 if report["ok"] else 1
