"""MQTT against a mosquitto with a password file, ACLs and a test CA made here.

Checks: the bridge connects with username/password over TLS; an ACL-denied publish never
reaches the daemon while an allowed user's does; anonymous clients are refused; the
password appears in no log line (ours or the broker's) and in no check-config output.
"""

from __future__ import annotations

import asyncio
import os
import subprocess
import sys
from collections.abc import AsyncIterator
from pathlib import Path

import aiomqtt
import pytest

from ptzd.mqtt.bridge import MqttBridge
from ptzd.mqtt.config import mqtt_config_from_url
from ptzd.mqtt.messages import Move, MoveDirection
from tests.mqtt_helpers import Broker, TlsFiles, make_tls_files

CAM = "cam1"
T = f"ptzd/{CAM}"
PASSWORDS = {"ptzd": "daemon-S3cret!", "viewer": "viewer-S3cret!", "operator": "op-S3cret!"}
ACL = f"""\
user ptzd
topic readwrite {T}/#
user viewer
topic read ptzd/#
user operator
topic write {T}/ptz
topic read {T}/#
"""


class AclBroker(Broker):
    """The test helper's broker plus an `acl_file`."""

    def _write_config(self) -> Path:
        conf = super()._write_config()
        acl = self.workdir / "acl"
        acl.write_text(ACL)
        acl.chmod(0o600)
        conf.write_text(conf.read_text() + f"acl_file {acl}\n")
        return conf


@pytest.fixture
async def secured(tmp_path: Path) -> AsyncIterator[tuple[AclBroker, TlsFiles]]:
    tls = make_tls_files(tmp_path)
    broker = AclBroker(tmp_path, passwords=PASSWORDS, tls=tls)
    broker.start()
    try:
        yield broker, tls
    finally:
        broker.stop()


def client(broker: Broker, tls: TlsFiles, user: str | None) -> aiomqtt.Client:
    return aiomqtt.Client(
        "127.0.0.1",
        broker.port,
        username=user,
        password=PASSWORDS[user] if user else None,
        tls_params=aiomqtt.TLSParameters(
            ca_certs=str(tls.ca), certfile=str(tls.client_cert), keyfile=str(tls.client_key)
        ),
        timeout=5,
    )


async def next_command(bridge: MqttBridge, limit_s: float) -> object | None:
    try:
        async with asyncio.timeout(limit_s):
            async for command in bridge.commands():
                return command
    except TimeoutError:
        return None
    return None


async def test_acl_denies_and_allows_and_nothing_leaks(
    secured: tuple[AclBroker, TlsFiles], capfd: pytest.CaptureFixture[str]
) -> None:
    broker, tls = secured
    cfg = mqtt_config_from_url(
        broker.url,
        username="ptzd",
        ca_file=tls.ca,
        cert_file=tls.client_cert,
        key_file=tls.client_key,
        reconnect_min_s=0.05,
        reconnect_max_s=0.3,
    )
    creds = broker.workdir / "creds"
    creds.mkdir()
    (creds / "mqtt-password").write_text(PASSWORDS["ptzd"] + "\n")
    async with MqttBridge(cfg, CAM, environ={"CREDENTIALS_DIRECTORY": str(creds)}) as bridge:
        await asyncio.wait_for(bridge.wait_connected(), 10)
        # a read-only user may watch but its command is dropped by the broker
        async with client(broker, tls, "viewer") as viewer:
            await viewer.publish(f"{T}/ptz", b"MOVE_LEFT", qos=1)
        assert await next_command(bridge, 1.0) is None
        # the operator is allowed to command: the same payload now arrives
        async with client(broker, tls, "operator") as operator:
            await operator.publish(f"{T}/ptz", b"MOVE_RIGHT", qos=1)
        assert await next_command(bridge, 5.0) == Move(MoveDirection.RIGHT)
        # anonymous and wrong-password clients are refused outright
        for user, password in ((None, None), ("viewer", "guess")):
            with pytest.raises(aiomqtt.MqttError):
                async with aiomqtt.Client(
                    "127.0.0.1",
                    broker.port,
                    username=user,
                    password=password,
                    tls_params=aiomqtt.TLSParameters(
                        ca_certs=str(tls.ca),
                        certfile=str(tls.client_cert),
                        keyfile=str(tls.client_key),
                    ),
                    timeout=5,
                ):
                    pass
        assert bridge.stats.commands_accepted == 1
    out, err = capfd.readouterr()
    logs = out + err + "".join(broker.log)
    for password in PASSWORDS.values():
        assert password not in logs


def test_check_config_never_prints_the_password(tmp_path: Path) -> None:
    config = tmp_path / "ptzd.toml"
    config.write_text('[mqtt]\nenabled = true\nusername = "ptzd"\n')
    config.chmod(0o600)
    env = {**os.environ, "PTZD_MQTT__PASSWORD": "hunter2-S3cret"}
    ok = subprocess.run(
        [sys.executable, "-m", "ptzd", "check-config", str(config)],
        capture_output=True, text=True, env=env, timeout=60,
    )  # fmt: skip
    assert ok.returncode == 0, ok.stderr
    assert "hunter2" not in ok.stdout + ok.stderr
    assert 'password = "**********"' in ok.stdout
    # an invalid config echoes offending values: never the password
    config.write_text('[mqtt]\nenabled = true\npassword = "hunter2-S3cret"\n')
    bad = subprocess.run(
        [sys.executable, "-m", "ptzd", "check-config", str(config)],
        capture_output=True, text=True, env={**os.environ}, timeout=60,
    )  # fmt: skip
    assert bad.returncode == 2
    assert "hunter2" not in bad.stdout + bad.stderr
