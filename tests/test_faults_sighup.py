"""SIGHUP to `ptzd run` (e.g. `kill -HUP`, or a controlling terminal hanging up).

Expected (docs/reliability.md): config reload is not supported; SIGHUP must be logged and
ignored, and the dome must never be left moving (`run_daemon` in ptzd/daemon_cli.py logs
`sighup_ignored`; without a handler the default action would kill it without the final STOP).
"""

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


def test_sighup_is_ignored_and_the_dome_keeps_being_driven(tmp_path: Path) -> None:
    video = tmp_path / "walk.avi"
    write_video(video, frames=200)
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
        stdout=subprocess.DEVNULL,
        stderr=subprocess.DEVNULL,
    )
    data = b""
    try:
        deadline = time.monotonic() + 30
        while time.monotonic() < deadline and len(data) < 40:
            with contextlib.suppress(BlockingIOError):
                data += os.read(master, 65536)
            time.sleep(0.05)
        proc.send_signal(signal.SIGHUP)
        time.sleep(1.0)
        alive_after_hup = proc.poll() is None
        proc.send_signal(signal.SIGTERM)
        proc.wait(timeout=20)
        with contextlib.suppress(BlockingIOError):
            while chunk := os.read(master, 65536):
                data += chunk
    finally:
        if proc.poll() is None:
            proc.kill()
        os.close(master)
        os.close(slave)
    motions = [f.command for f in FrameParser().feed(data) if isinstance(f.command, Motion)]
    assert alive_after_hup, "SIGHUP killed the daemon"
    assert proc.returncode == 0
    assert motions[-1] == Motion()
