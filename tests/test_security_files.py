"""`ptzd check-config` warns about secret files other users can read; units never run as root."""

from __future__ import annotations

import os
import subprocess
import sys
from pathlib import Path

import pytest

from ptzd.config import validate_config
from ptzd.config_cli import secret_file_warnings
from tests.test_systemd_units import UNITS, directives


def check_config(path: Path, env: dict[str, str]) -> subprocess.CompletedProcess[str]:
    return subprocess.run(
        [sys.executable, "-m", "ptzd", "check-config", str(path)],
        capture_output=True, text=True, env={**os.environ, **env}, timeout=60,
    )  # fmt: skip


def test_world_readable_credential_and_key_are_warned_about(tmp_path: Path) -> None:
    creds = tmp_path / "creds"
    creds.mkdir()
    secret = creds / "mqtt-password"
    secret.write_text("pw\n")
    key = tmp_path / "client.key"
    key.write_text("-----BEGIN PRIVATE KEY-----\n")
    config = tmp_path / "ptzd.toml"
    config.write_text(
        '[mqtt]\nenabled = true\nurl = "mqtts://broker:8883"\nusername = "ptzd"\n'
        f'cert_file = "{tmp_path / "client.pem"}"\nkey_file = "{key}"\n'
    )
    env = {"CREDENTIALS_DIRECTORY": str(creds)}
    secret.chmod(0o644)
    key.chmod(0o604)
    run = check_config(config, env)
    assert run.returncode == 0  # a warning, not an error: the config itself is valid
    warnings = [line for line in run.stderr.splitlines() if "warning" in line]
    assert any("mqtt.password_credential" in w and "0644" in w for w in warnings), run.stderr
    assert any("mqtt.key_file" in w and "0604" in w for w in warnings), run.stderr
    assert "pw" not in run.stdout.replace("password", "")
    secret.chmod(0o600)
    key.chmod(0o640)  # group-readable is the admin's choice (e.g. a ptzd group)
    assert "warning" not in check_config(config, env).stderr


def test_password_in_a_world_readable_config_file_is_warned_about(tmp_path: Path) -> None:
    path = tmp_path / "ptzd.toml"
    path.write_text('[mqtt]\nusername = "u"\npassword = "p"\n')
    config = validate_config({"mqtt": {"username": "u", "password": "p"}}, environ={})
    path.chmod(0o644)
    assert [w.split(":")[0] for w in secret_file_warnings(config, path, {})] == ["mqtt.password"]
    path.chmod(0o600)
    assert secret_file_warnings(config, path, {}) == []


@pytest.mark.parametrize("unit", sorted(p.name for p in UNITS.glob("*.service")))
def test_units_never_run_ptzd_as_root(unit: str) -> None:
    d = directives(UNITS / unit)
    one = {k: v[-1] for k, v in d.items()}
    assert one.get("User", "") not in ("root", "0")
    assert one.get("Group", "") not in ("root", "0")
    # either a dynamic user or a named unprivileged one; never the default (root)
    assert one.get("DynamicUser") == "yes" or one.get("User")
    # "+" / "!" / "!!" prefixes run a command with full privileges despite User=
    for key in ("ExecStart", "ExecStartPre", "ExecStartPost", "ExecReload", "ExecStop"):
        for command in d.get(key, []):
            assert not command.lstrip("-@:").startswith(("+", "!")), (key, command)
    assert one.get("NoNewPrivileges") == "yes"
    assert one.get("CapabilityBoundingSet") == ""
    assert one.get("AmbientCapabilities", "") == ""
