"""`ptzd run` as a process: a real video file, a real pty, SIGTERM -> orderly STOP."""

from __future__ import annotations

import contextlib
import os
import signal
import subprocess
import sys
import time
import tty
from pathlib import Path

from ptzd.pelco.codec import FrameParser, Motion
from tests.test_app_capture import write_video


def test_sigterm_stops_the_dome(tmp_path: Path) -> None:
    video = tmp_path / "walk.avi"
    write_video(video)
    master, slave = os.openpty()
    tty.setraw(slave)
    os.set_blocking(master, False)
    config = tmp_path / "ptzd.toml"
    config.write_text(
        f'[capture]\nsource = "{video}"\n[serial]\nport = "{os.ttyname(slave)}"\n'
        '[logging]\nformat = "json"\n'
    )
    proc = subprocess.Popen(
        [sys.executable, "-m", "ptzd", "run", "--config", str(config), "--init", "150,90,20,60"],
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
    )
    data = b""

    def drain() -> None:
        nonlocal data
        with contextlib.suppress(BlockingIOError):
            while chunk := os.read(master, 65536):
                data += chunk

    try:
        deadline = time.monotonic() + 30
        parser = FrameParser()
        moved = False
        while time.monotonic() < deadline and not moved:
            before = len(data)
            drain()
            moved = any(
                isinstance(f.command, Motion) and f.command.pan > 0
                for f in parser.feed(data[before:])
            )
            time.sleep(0.05)
        assert moved, "the dome never panned right after the target"
        proc.send_signal(signal.SIGTERM)
        _, stderr = proc.communicate(timeout=20)
        drain()
    finally:
        if proc.poll() is None:
            proc.kill()
        os.close(master)
        os.close(slave)
    assert proc.returncode == 0, stderr.decode()
    frames = FrameParser().feed(data)
    motions = [f.command for f in frames if isinstance(f.command, Motion)]
    assert motions[0] == Motion() and motions[-1] == Motion()
