"""Logging: JSON lines off a TTY, camera and stage bound, journald priority prefix."""

from __future__ import annotations

import io
import json

import pytest

from ptzd.logs import configure_logging, get_logger


def test_json_lines_with_camera_and_stage(monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.delenv("JOURNAL_STREAM", raising=False)
    out = io.StringIO()
    configure_logging(level="info", fmt="auto", camera="gate", stream=out)
    log = get_logger("control")
    log.info("moved", pan=12)
    log.debug("hidden")
    lines = out.getvalue().splitlines()
    assert len(lines) == 1
    event = json.loads(lines[0])
    assert event["event"] == "moved"
    assert event["camera"] == "gate"
    assert event["stage"] == "control"
    assert event["pan"] == 12
    assert event["level"] == "info"


def test_journald_priority_prefix(monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.setenv("JOURNAL_STREAM", "8:12345")
    out = io.StringIO()
    configure_logging(level="debug", fmt="json", camera="c", stream=out)
    get_logger("serial").warning("port vanished")
    line = out.getvalue().strip()
    assert line.startswith("<4>{")
    assert json.loads(line[3:])["event"] == "port vanished"


def test_console_format_is_not_json(monkeypatch: pytest.MonkeyPatch) -> None:
    out = io.StringIO()
    configure_logging(level="info", fmt="console", camera="c", stream=out)
    get_logger("x").info("hello")
    text = out.getvalue()
    assert "hello" in text
    with pytest.raises(json.JSONDecodeError):
        json.loads(text)


def test_a_logger_made_before_reconfiguring_follows_the_new_configuration(
    monkeypatch: pytest.MonkeyPatch,
) -> None:
    # module-level loggers exist before the CLI has read the config (`ptzd run` reconfigures)
    monkeypatch.delenv("JOURNAL_STREAM", raising=False)
    first = io.StringIO()
    configure_logging(level="info", fmt="json", camera="-", stream=first)
    log = get_logger("daemon")
    second = io.StringIO()
    configure_logging(level="warning", fmt="json", camera="gate", stream=second)
    log.info("below the new level")
    log.warning("kept")
    assert first.getvalue() == ""
    events = [json.loads(line) for line in second.getvalue().splitlines()]
    assert [(e["event"], e["camera"], e["stage"]) for e in events] == [("kept", "gate", "daemon")]
