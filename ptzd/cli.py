"""The `ptzd` command line: one subcommand per capability.

Each stage registers its own subcommands (`register(subparsers)` in its `cli` module) and
imports its heavy dependencies inside the handler, so `ptzd pelco encode` stays fast.
Handlers return an exit code; `UsageError` and `ConfigError` become one-line messages and
exit status 2.
"""

from __future__ import annotations

import argparse
import importlib
import sys
from collections.abc import Sequence
from typing import NoReturn

from ptzd import __version__
from ptzd.errors import ConfigError, UsageError

# Modules with a `register(subparsers)` function, in the order their commands are listed.
COMMAND_MODULES = (
    "ptzd.config_cli",
    "ptzd.pelco.cli",
    "ptzd.sim.cli",
    "ptzd.vision.cli",
    "ptzd.vision.detect_cli",
    "ptzd.daemon_cli",
    "ptzd.soak_cli",
)

EXIT_USAGE = 2


class ArgumentParser(argparse.ArgumentParser):
    """argparse with a one-line error and exit status 2."""

    def error(self, message: str) -> NoReturn:
        self.exit(EXIT_USAGE, f"{self.prog}: error: {message}\n")


def build_parser() -> ArgumentParser:
    parser = ArgumentParser(prog="ptzd", description="PTZ camera auto-tracking daemon")
    parser.add_argument("--version", action="version", version=f"ptzd {__version__}")
    parser.add_argument(
        "--log-level",
        choices=["debug", "info", "warning", "error"],
        default=None,
        help="override the configured log level",
    )
    parser.add_argument(
        "--log-format",
        choices=["auto", "json", "console"],
        default=None,
        help="console on a TTY and JSON otherwise unless set",
    )
    subparsers = parser.add_subparsers(
        dest="command", metavar="COMMAND", parser_class=ArgumentParser
    )
    subparsers.required = True
    for name in COMMAND_MODULES:
        importlib.import_module(name).register(subparsers)
    return parser


# options whose value is a box "X,Y,W,H": a box partly off the frame's left or top edge
# starts with a minus, which argparse takes for an option unless it is a plain number
BOX_OPTIONS = ("--init",)


def attach_negative_boxes(argv: Sequence[str]) -> list[str]:
    """`--init -5,100,30,60` as `--init=-5,100,30,60`, so argparse reads it as the value."""
    out: list[str] = []
    for arg in argv:
        if out and out[-1] in BOX_OPTIONS and arg[:1] == "-" and arg[1:2].isdigit():
            out[-1] = f"{out[-1]}={arg}"
        else:
            out.append(arg)
    return out


def main(argv: Sequence[str] | None = None) -> int:
    parser = build_parser()
    args = parser.parse_args(attach_negative_boxes(sys.argv[1:] if argv is None else argv))
    from ptzd.logs import configure_logging

    configure_logging(level=args.log_level or "info", fmt=args.log_format or "auto")
    try:
        code: int = args.handler(args)
    except UsageError as exc:
        print(f"ptzd: error: {exc}", file=sys.stderr)
        return EXIT_USAGE
    except ConfigError as exc:
        for key, msg, value in exc.problems:
            print(f"{exc.source}: {key}: {msg} (got {value!r})", file=sys.stderr)
        return EXIT_USAGE
    except KeyboardInterrupt:
        return 130
    return code
