"""The shipped systemd units: required directives, and `systemd-analyze verify` when present."""

from __future__ import annotations

import shutil
import subprocess
import sys
from pathlib import Path

import pytest

UNITS = Path(__file__).resolve().parents[1] / "systemd"


def directives(path: Path) -> dict[str, list[str]]:
    """`Key=value` lines of a unit; repeated keys keep every value (in order)."""
    found: dict[str, list[str]] = {}
    for raw in path.read_text().splitlines():
        line = raw.strip()
        if not line or line.startswith(("#", ";", "[")):
            continue
        key, _, value = line.partition("=")
        found.setdefault(key.strip(), []).append(value.strip())
    return found


@pytest.mark.parametrize("name", ["ptzd.service", "ptzd@.service"])
def test_unit_is_notify_watchdogged_and_hardened(name: str) -> None:
    d = directives(UNITS / name)
    one = {k: v[-1] for k, v in d.items()}
    assert one["Type"] == "notify"
    assert one["NotifyAccess"] == "main"
    assert int(one["WatchdogSec"].rstrip("s")) >= 10
    assert one["Restart"] == "on-failure"
    assert int(one["TimeoutStopSec"].rstrip("s")) >= 10  # room for STOP + MQTT offline
    assert one["DevicePolicy"] == "closed"
    assert d["DeviceAllow"][:2] == ["char-ttyUSB rw", "char-ttyACM rw"]
    assert "dialout" in one["SupplementaryGroups"].split()
    assert one["DynamicUser"] == "yes"
    assert one["ProtectSystem"] == "strict"
    assert one["ProtectHome"] == "yes"
    assert one["NoNewPrivileges"] == "yes"
    assert one["RestrictAddressFamilies"].split() == ["AF_UNIX", "AF_INET", "AF_INET6"]
    assert d["SystemCallFilter"][0] == "@system-service"
    assert one["CapabilityBoundingSet"] == ""
    assert one["LoadCredential"].startswith("mqtt-password:/etc/ptzd/credentials/")
    assert "PrivateDevices" not in d  # would hide the serial adapter


def test_template_takes_instance_config() -> None:
    one = {k: v[-1] for k, v in directives(UNITS / "ptzd@.service").items()}
    assert one["ExecStart"].endswith("ptzd run --config /etc/ptzd/%i.toml")
    assert "%i" in one["LoadCredential"]
    single = {k: v[-1] for k, v in directives(UNITS / "ptzd.service").items()}
    assert single["ExecStart"].endswith("ptzd run --config /etc/ptzd/ptzd.toml")


def test_systemd_analyze_verify(tmp_path: Path) -> None:
    analyze = shutil.which("systemd-analyze")
    if analyze is None:
        pytest.skip("systemd-analyze not installed")
    ptzd_bin = Path(sys.executable).with_name("ptzd")
    if not ptzd_bin.exists():
        pytest.skip(f"{ptzd_bin} not installed (editable install missing)")
    # verify checks that ExecStart exists: point it at this checkout's entry point
    for name, target in [("ptzd.service", "ptzd.service"), ("ptzd@.service", "ptzd@cam1.service")]:
        text = (UNITS / name).read_text().replace("/opt/ptzd/venv/bin/ptzd", str(ptzd_bin))
        (tmp_path / name).write_text(text)
        if target != name:
            (tmp_path / target).write_text(text)
    out = subprocess.run(
        [analyze, "verify", "--man=no", "ptzd.service", "ptzd@cam1.service"],
        cwd=tmp_path,
        capture_output=True,
        text=True,
        timeout=60,
    )
    if out.returncode != 0 and "Failed to" in out.stderr and "bus" in out.stderr.lower():
        pytest.skip(f"systemd-analyze cannot run here: {out.stderr.strip()[:200]}")
    # unknown keys and bad values are only warnings (exit 0): demand silence
    assert out.returncode == 0, out.stderr
    assert out.stderr.strip() == "", out.stderr
