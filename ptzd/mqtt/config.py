"""Configuration of the MQTT bridge (`[mqtt]`).

Secrets never live in the TOML file: the password comes from systemd's credential
directory (`LoadCredential=`), or from the environment as `PTZD_MQTT__PASSWORD`, and is
held as a `SecretStr` so `ptzd check-config` and the logs only ever show `**********`.
"""

from __future__ import annotations

import os
from collections.abc import Mapping
from dataclasses import dataclass
from pathlib import Path
from typing import Self
from urllib.parse import urlsplit

from pydantic import Field, SecretStr, model_validator

from ptzd.errors import ConfigError
from ptzd.schema import StrictModel

MQTT_SCHEMES = {"mqtt": 1883, "mqtts": 8883}


@dataclass(frozen=True)
class BrokerAddress:
    """Where the broker is, parsed from `mqtt.url`."""

    host: str
    port: int
    tls: bool


def parse_broker_url(url: str) -> BrokerAddress:
    """`mqtt://host[:port]` or `mqtts://host[:port]`; raise `ValueError` naming the problem."""
    parts = urlsplit(url)
    if parts.scheme not in MQTT_SCHEMES:
        raise ValueError(f"scheme must be mqtt:// or mqtts://, got {parts.scheme or 'none'!r}")
    if parts.username or parts.password:
        raise ValueError("credentials do not belong in the URL: use mqtt.username and a credential")
    if parts.path not in ("", "/") or parts.query or parts.fragment:
        raise ValueError("the URL takes no path, query or fragment")
    try:
        port = parts.port
    except ValueError as exc:  # port out of range or not a number
        raise ValueError(f"bad port: {exc}") from None
    if not parts.hostname:
        raise ValueError("missing host")
    return BrokerAddress(
        host=parts.hostname,
        port=port if port is not None else MQTT_SCHEMES[parts.scheme],
        tls=parts.scheme == "mqtts",
    )


class MqttConfig(StrictModel):
    """Broker, credentials, TLS, topic prefix, rates and limits of the MQTT bridge."""

    enabled: bool = False
    url: str = Field(default="mqtt://localhost:1883", min_length=1, max_length=512)
    prefix: str = Field(default="ptzd", pattern=r"^[A-Za-z0-9_\-]+(/[A-Za-z0-9_\-]+)*$")
    client_id: str = Field(default="", pattern=r"^[A-Za-z0-9_\-]{0,64}$")
    username: str = Field(default="", max_length=256)
    password: SecretStr | None = None
    password_credential: str = Field(default="mqtt-password", pattern=r"^[A-Za-z0-9_.\-]{1,64}$")
    ca_file: Path | None = None
    cert_file: Path | None = None
    key_file: Path | None = None
    keepalive_s: int = Field(default=30, ge=5, le=3600)
    timeout_s: float = Field(default=5.0, ge=0.5, le=60.0)
    track_rate_hz: float = Field(default=10.0, gt=0.0, le=1000.0)
    reconnect_min_s: float = Field(default=0.5, gt=0.0, le=60.0)
    reconnect_max_s: float = Field(default=30.0, gt=0.0, le=3600.0)
    max_payload_bytes: int = Field(default=1024, ge=64, le=65536)
    command_queue_size: int = Field(default=32, ge=1, le=1024)
    discovery: bool = False
    discovery_prefix: str = Field(
        default="homeassistant", pattern=r"^[A-Za-z0-9_\-]+(/[A-Za-z0-9_\-]+)*$"
    )

    @model_validator(mode="after")
    def _check_cross_fields(self) -> Self:
        try:
            broker = parse_broker_url(self.url)
        except ValueError as exc:
            raise ValueError(f"url: {exc}") from None
        if self.reconnect_min_s > self.reconnect_max_s:
            raise ValueError("reconnect_min_s must not exceed reconnect_max_s")
        if (self.cert_file is None) != (self.key_file is None):
            raise ValueError("cert_file and key_file go together: set both or neither")
        tls_files = [self.ca_file, self.cert_file, self.key_file]
        if not broker.tls and any(f is not None for f in tls_files):
            raise ValueError("ca_file/cert_file/key_file need an mqtts:// url")
        if self.password is not None and not self.username:
            raise ValueError("password given without username")
        return self

    @property
    def broker(self) -> BrokerAddress:
        return parse_broker_url(self.url)


def mqtt_config_from_url(url: str, **overrides: object) -> MqttConfig:
    """An enabled `MqttConfig` for `url` (the `ptzd sim --mqtt-url` flag), other keys default.

    Raises `ConfigError` naming `mqtt.url` (or the overridden key) when invalid.
    """
    from ptzd.config import validate_config  # ptzd.config imports this module

    section = {"enabled": True, "url": url, **overrides}
    return validate_config({"mqtt": section}, source="--mqtt-url", environ={}).mqtt


def resolve_password(
    config: MqttConfig, environ: Mapping[str, str] | None = None
) -> SecretStr | None:
    """The broker password: `mqtt.password` (e.g. `PTZD_MQTT__PASSWORD`) if set, else the
    systemd credential `$CREDENTIALS_DIRECTORY/<password_credential>` if present, else None.

    Reads a file, so call it when connecting, never from a constructor. Trailing newlines
    of the credential file are stripped (editors and `echo` add one).
    """
    if config.password is not None:
        return config.password
    env = os.environ if environ is None else environ
    directory = env.get("CREDENTIALS_DIRECTORY")
    if not directory:
        return None
    path = Path(directory) / config.password_credential
    try:
        text = path.read_text(encoding="utf-8")
    except FileNotFoundError:
        return None
    except (OSError, UnicodeDecodeError) as exc:
        raise ConfigError(
            str(path), [("mqtt.password_credential", f"unreadable credential: {exc}", None)]
        ) from None
    return SecretStr(text.rstrip("\r\n"))
