"""Logging, configured once: console on a TTY, JSON lines otherwise.

Every logger from `get_logger(stage)` carries `stage`, and every event carries the
configured `camera`. Under systemd (journald sets `$JOURNAL_STREAM`) JSON lines get a
`<N>` syslog priority prefix so `journalctl -p warning` works.
"""

from __future__ import annotations

import logging
import os
import sys
from typing import Any, Literal, TextIO

import structlog
from structlog.typing import EventDict, FilteringBoundLogger, Processor, WrappedLogger

LogFormat = Literal["auto", "json", "console"]

_LEVELS = {
    "debug": logging.DEBUG,
    "info": logging.INFO,
    "warning": logging.WARNING,
    "error": logging.ERROR,
    "critical": logging.CRITICAL,
}
# syslog priorities (RFC 5424) by structlog level name
_SYSLOG_PRIORITY = {"debug": 7, "info": 6, "warning": 4, "error": 3, "critical": 2, "exception": 3}

_camera = "-"


def _add_camera(_logger: WrappedLogger, _name: str, event: EventDict) -> EventDict:
    event.setdefault("camera", _camera)
    return event


class _SyslogPrefixedJSON:
    """Renders JSON and prefixes `<priority>` for journald's stdout stream parser."""

    def __init__(self) -> None:
        self._json = structlog.processors.JSONRenderer(sort_keys=False)

    def __call__(self, logger: WrappedLogger, name: str, event: EventDict) -> str:
        priority = _SYSLOG_PRIORITY.get(str(event.get("level", "info")), 6)
        rendered = self._json(logger, name, event)
        text = rendered.decode() if isinstance(rendered, bytes) else rendered
        return f"<{priority}>{text}"


def _wants_console(fmt: LogFormat, stream: TextIO) -> bool:
    if fmt == "auto":
        return stream.isatty()
    return fmt == "console"


def configure_logging(
    *,
    level: str = "info",
    fmt: LogFormat = "auto",
    camera: str = "-",
    stream: TextIO | None = None,
) -> None:
    """Configure structlog for the whole process. Call once, early, from the CLI."""
    global _camera
    _camera = camera
    out = stream if stream is not None else sys.stderr
    shared: list[Processor] = [
        structlog.contextvars.merge_contextvars,
        structlog.processors.add_log_level,
        _add_camera,
        structlog.processors.TimeStamper(fmt="iso", utc=True),
        structlog.processors.StackInfoRenderer(),
    ]
    renderer: Processor
    if _wants_console(fmt, out):
        renderer = structlog.dev.ConsoleRenderer(colors=out.isatty())
    else:
        shared.append(structlog.processors.format_exc_info)
        renderer = (
            _SyslogPrefixedJSON()
            if os.environ.get("JOURNAL_STREAM")
            else structlog.processors.JSONRenderer()
        )
    structlog.configure(
        processors=[*shared, renderer],
        wrapper_class=structlog.make_filtering_bound_logger(_LEVELS[level]),
        logger_factory=structlog.PrintLoggerFactory(file=out),
        cache_logger_on_first_use=False,
    )


def get_logger(stage: str, **bound: Any) -> FilteringBoundLogger:
    """A logger bound to `stage` (and anything else given)."""
    # A lazy proxy, not `.bind()` now: module-level loggers are made at import time, before
    # the CLI has read the config, and must follow a later `configure_logging` call.
    logger: FilteringBoundLogger = structlog.get_logger(stage=stage, **bound)
    return logger
