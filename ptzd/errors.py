"""Exceptions shared across stages.

Each carries the data a caller needs to act on it, not just a message.
"""

from __future__ import annotations


class PtzdError(Exception):
    """Base class of every error ptzd raises on purpose."""


class UsageError(PtzdError):
    """A command-line or input problem the user must fix; the CLI prints it and exits 2."""


class ConfigError(PtzdError):
    """A configuration file that cannot be loaded or does not validate.

    `problems` holds one `(key_path, message, offending_value)` tuple per error, so
    `ptzd check-config` can print each with its key.
    """

    def __init__(self, source: str, problems: list[tuple[str, str, object]]) -> None:
        self.source = source
        self.problems = problems
        lines = "; ".join(f"{key}: {msg}" for key, msg, _ in problems)
        super().__init__(f"{source}: {lines}")
