"""`ptzd pelco encode|decode|send|demo` as subprocesses (the external contract)."""

from __future__ import annotations

import json
import os
import subprocess
import sys
import tty

import pytest

from ptzd.pelco.codec import FrameParser, Motion, Preset, PresetAction


def ptzd(*args: str, timeout: float = 60) -> subprocess.CompletedProcess[str]:
    return subprocess.run(
        [sys.executable, "-m", "ptzd", "--log-format", "json", "pelco", *args],
        capture_output=True,
        text=True,
        timeout=timeout,
    )


@pytest.mark.parametrize(
    ("args", "expected"),
    [
        (["--protocol", "p", "--address", "1", "--pan", "-32"], "a0 00 00 04 20 00 af 2b"),
        (["--protocol", "p", "--address", "1", "--pan", "32"], "a0 00 00 02 20 00 af 2d"),
        (["--protocol", "p", "--address", "1", "--tilt", "32"], "a0 00 00 08 00 20 af 27"),
        (["--protocol", "p", "--address", "1"], "a0 00 00 00 00 00 af 0f"),
        (["--protocol", "d", "--address", "1", "--pan", "-32"], "ff 01 00 04 20 00 25"),
        (["--protocol", "d", "--address", "1", "--pan", "64"], "ff 01 00 02 ff 00 02"),
        (["--protocol", "p", "--address", "1", "--zoom", "in"], "a0 00 00 20 00 00 af 2f"),
        (["--protocol", "d", "--address", "2", "--preset", "goto", "5"], "ff 02 00 07 00 05 0e"),
    ],
)
def test_encode(args: list[str], expected: str) -> None:
    result = ptzd("encode", *args)
    assert result.returncode == 0, result.stderr
    assert result.stdout == expected + "\n"


def test_decode_prints_one_json_object_per_valid_frame() -> None:
    result = ptzd(
        "decode",
        "00 13 a0 00 00 04 20 00 af 2b",  # garbage, then pan left
        "a0 00 00 04 20 00 af 2c",  # bad checksum
        "ff0200070005 0e",  # spacing is free
    )
    assert result.returncode == 0, result.stderr
    lines = [json.loads(line) for line in result.stdout.splitlines()]
    assert lines == [
        {
            "protocol": "p",
            "address": 1,
            "command": "motion",
            "pan": -32,
            "tilt": 0,
            "zoom": "none",
            "focus": 0,
            "iris": 0,
            "hex": "a0 00 00 04 20 00 af 2b",
        },
        {
            "protocol": "d",
            "address": 2,
            "command": "preset",
            "action": "goto",
            "number": 5,
            "hex": "ff 02 00 07 00 05 0e",
        },
    ]


@pytest.mark.parametrize(
    "args",
    [
        ["encode", "--protocol", "p", "--address", "1", "--pan", "65"],
        ["encode", "--protocol", "p", "--address", "0"],
        ["encode", "--protocol", "d", "--address", "256"],
        ["encode", "--protocol", "x", "--address", "1"],
        ["encode", "--protocol", "p", "--address", "1", "--tilt", "64"],
        ["encode", "--protocol", "p", "--address", "1", "--preset", "jump", "3"],
        ["encode", "--protocol", "p", "--address", "1", "--preset", "goto", "0"],
        ["encode", "--protocol", "p", "--address", "1", "--preset", "goto", "x"],
        ["encode", "--protocol", "p", "--address", "1", "--preset", "goto", "3", "--pan", "4"],
        ["decode", "a0 zz"],
        ["decode", "a0 0"],
        ["send", "--port", "/dev/does-not-exist-ptzd", "--protocol", "p", "--address", "1"],
    ],
)
def test_bad_arguments_exit_2_with_one_line(args: list[str]) -> None:
    result = ptzd(*args)
    assert result.returncode == 2
    errors = [line for line in result.stderr.splitlines() if "error" in line]
    assert len(errors) == 1, result.stderr


def test_send_moves_then_stops() -> None:
    master, slave = os.openpty()
    tty.setraw(slave)
    try:
        result = ptzd(
            "send", "--port", os.ttyname(slave), "--protocol", "p", "--address", "3",
            "--pan", "-20", "--for", "0.3",
        )  # fmt: skip
        os.set_blocking(master, False)
        data = os.read(master, 4096)
    finally:
        os.close(master)
        os.close(slave)
    assert result.returncode == 0, result.stderr
    frames = FrameParser().feed(data)
    assert {f.address for f in frames} == {3}
    assert [f.command for f in frames] == [Motion(), Motion(), Motion(pan=-20), Motion(), Motion()]


def test_send_a_preset() -> None:
    master, slave = os.openpty()
    tty.setraw(slave)
    try:
        result = ptzd(
            "send", "--port", os.ttyname(slave), "--protocol", "d", "--address", "1",
            "--preset", "set", "9", "--for", "0.2",
        )  # fmt: skip
        os.set_blocking(master, False)
        data = os.read(master, 4096)
    finally:
        os.close(master)
        os.close(slave)
    assert result.returncode == 0, result.stderr
    commands = [f.command for f in FrameParser().feed(data)]
    assert Preset(PresetAction.SET, 9) in commands and commands[-1] == Motion()


def test_demo_is_bounded_and_shows_coalescing_and_the_deadman() -> None:
    result = ptzd("demo", "--seconds", "5", timeout=30)
    assert result.returncode == 0, result.stderr
    lines = [json.loads(line) for line in result.stdout.splitlines()]
    frames, summary = lines[:-1], lines[-1]["link_counters"]
    assert frames[0]["command"] == "motion" and frames[0]["pan"] == 0
    assert any(f["command"] == "preset" and f["action"] == "goto" for f in frames)
    assert summary["coalesced"] > 10
    assert summary["deadman_stops"] == 1
    assert frames[-1]["pan"] == 0 and frames[-1]["tilt"] == 0
    assert max(f["t"] for f in frames) < 6.0
