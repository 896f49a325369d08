"""Configuration: loading, validation errors with key paths, env overrides, check-config."""

from __future__ import annotations

import subprocess
import sys
import tomllib
from pathlib import Path
from typing import Any

import pytest
from pydantic import BaseModel

from ptzd.config import Config, env_overrides, load_config, to_toml, validate_config
from ptzd.errors import ConfigError

SHIPPED = Path(__file__).resolve().parents[1] / "config" / "ptzd.toml"


def _ptzd(*args: str, env: dict[str, str] | None = None) -> subprocess.CompletedProcess[str]:
    return subprocess.run(
        [sys.executable, "-m", "ptzd", *args], capture_output=True, text=True, env=env, timeout=60
    )


def _keys(model: type[BaseModel], prefix: str = "") -> set[str]:
    keys: set[str] = set()
    for name, field in model.model_fields.items():
        ann = field.annotation
        if isinstance(ann, type) and issubclass(ann, BaseModel):
            keys |= _keys(ann, f"{prefix}{name}.")
        else:
            keys.add(f"{prefix}{name}")
    return keys


def _commented_keys(text: str) -> set[str]:
    """Keys set in the file or shown commented out (`# key = value`), with their table."""
    keys: set[str] = set()
    table: str | None = None  # keys before the first table are prose, not config
    for raw in text.splitlines():
        line = raw.strip()
        if line.startswith("[") and line.endswith("]"):
            table = line.strip("[]").strip() + "."
            continue
        body = line.lstrip("#").strip()
        if table is not None and "=" in body and not body.startswith(("-", "[")):
            key = body.split("=", 1)[0].strip()
            if key.replace("_", "").isalnum() and " " not in key:
                keys.add(table + key)
    return keys


def test_shipped_config_is_valid_and_equals_defaults() -> None:
    config = load_config(SHIPPED, environ={})
    assert config == Config()


def test_shipped_config_documents_every_key() -> None:
    text = SHIPPED.read_text()
    documented = _commented_keys(text)
    missing = _keys(Config) - documented
    assert not missing, f"keys not documented in config/ptzd.toml: {sorted(missing)}"
    # and nothing documented that the model does not know
    unknown = documented - _keys(Config)
    assert not unknown, f"documented keys the model does not have: {sorted(unknown)}"


def test_errors_name_key_path_and_value(tmp_path: Path) -> None:
    bad = tmp_path / "bad.toml"
    bad.write_text('[serial]\naddress = 0\nprotocol = "x"\n[control]\nrate_hz = -1\nbogus = 1\n')
    with pytest.raises(ConfigError) as info:
        load_config(bad, environ={})
    keys = {key: value for key, _, value in info.value.problems}
    assert keys["serial.address"] == 0
    assert keys["serial.protocol"] == "x"
    assert keys["control.rate_hz"] == -1
    assert keys["control.bogus"] == 1


def test_unreadable_and_malformed_files(tmp_path: Path) -> None:
    with pytest.raises(ConfigError) as info:
        load_config(tmp_path / "missing.toml", environ={})
    assert info.value.problems[0][0] == "<file>"
    broken = tmp_path / "broken.toml"
    broken.write_text("[serial\nport = 1\n")
    with pytest.raises(ConfigError) as info:
        load_config(broken, environ={})
    assert info.value.problems[0][0] == "<toml>"


def test_env_overrides_are_typed_and_nested() -> None:
    env = {
        "PTZD_SERIAL__PORT": "socket://localhost:4001",
        "PTZD_SERIAL__ADDRESS": "7",
        "PTZD_CONTROL__RATE_HZ": "25.5",
        "PTZD_MQTT__ENABLED": "true",
        "PTZD_UNRELATED": "ignored",
    }
    tree: dict[str, Any] = env_overrides(env)
    assert tree == {
        "serial": {"port": "socket://localhost:4001", "address": 7},
        "control": {"rate_hz": 25.5},
        "mqtt": {"enabled": True},
    }
    config = validate_config({"serial": {"address": 3}}, environ=env)
    assert config.serial.address == 7
    assert config.serial.port == "socket://localhost:4001"
    assert config.control.rate_hz == 25.5
    assert config.mqtt.enabled is True


def test_env_override_errors_name_the_key() -> None:
    with pytest.raises(ConfigError) as info:
        validate_config({}, environ={"PTZD_SERIAL__ADDRESS": "999"})
    assert info.value.problems[0][0] == "serial.address"


def test_config_is_frozen() -> None:
    config = Config()
    with pytest.raises(Exception, match="frozen"):
        config.serial.address = 5  # type: ignore[misc]


def test_to_toml_round_trips() -> None:
    config = validate_config({"serial": {"port": 'we"ird', "baudrate": 9600}}, environ={})
    assert Config.model_validate(tomllib.loads(to_toml(config))) == config


def test_check_config_cli(tmp_path: Path) -> None:
    good = _ptzd("check-config", str(SHIPPED), env={"PATH": "/usr/bin:/bin"})
    assert good.returncode == 0, good.stderr
    assert Config.model_validate(tomllib.loads(good.stdout)) == Config()

    bad = tmp_path / "bad.toml"
    bad.write_text("[serial]\naddress = 300\n")
    result = _ptzd("check-config", str(bad), env={"PATH": "/usr/bin:/bin"})
    assert result.returncode == 2
    assert "serial.address" in result.stderr
    assert "300" in result.stderr


def test_cli_bad_arguments_exit_2_with_one_line() -> None:
    result = _ptzd("no-such-command")
    assert result.returncode == 2
    assert len(result.stderr.strip().splitlines()) == 1
