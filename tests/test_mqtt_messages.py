"""Pure parts of the MQTT interface: command parsing, payloads, config, secrets, backoff."""

from __future__ import annotations

import json
import random
import subprocess
import sys
from enum import StrEnum
from pathlib import Path

import pytest
from hypothesis import given
from hypothesis import strategies as st
from pydantic import SecretStr, ValidationError

from ptzd.backoff import backoff_delay
from ptzd.config import Config, to_toml, validate_config
from ptzd.errors import ConfigError
from ptzd.mqtt.bridge import MqttBridge
from ptzd.mqtt.config import MqttConfig, mqtt_config_from_url, parse_broker_url, resolve_password
from ptzd.mqtt.messages import (
    CommandError,
    GotoPreset,
    Move,
    MoveDirection,
    PtzState,
    SelectTarget,
    SetAutotrack,
    Stop,
    Topics,
    TrackMessage,
    TrackState,
    ZoomDirection,
    ZoomMove,
    parse_autotrack,
    parse_ptz,
)

TOPIC = "ptzd/cam1/ptz"


def test_topics_match_the_interface_contract() -> None:
    t = Topics("ptzd", "cam1")
    assert t.availability == "ptzd/cam1/availability"
    assert t.track == "ptzd/cam1/track"
    assert t.zoom_layer == "ptzd/cam1/zoom_layer"
    assert t.autotrack_set == "ptzd/cam1/autotrack/set"
    assert t.autotrack_state == "ptzd/cam1/autotrack/state"
    assert t.ptz == "ptzd/cam1/ptz"
    assert t.ptz_state == "ptzd/cam1/ptz/state"
    assert t.error == "ptzd/cam1/error"


@pytest.mark.parametrize(
    ("payload", "expected"),
    [
        (b"preset_1", GotoPreset(1)),
        (b"PRESET_255", GotoPreset(255)),
        (b"MOVE_LEFT", Move(MoveDirection.LEFT)),
        (b"Move_Right", Move(MoveDirection.RIGHT)),
        (b"MOVE_UP\n", Move(MoveDirection.UP)),
        (b"MOVE_DOWN", Move(MoveDirection.DOWN)),
        (b"ZOOM_IN", ZoomMove(ZoomDirection.IN)),
        (b"zoom_out", ZoomMove(ZoomDirection.OUT)),
        (b"STOP", Stop()),
        (b'{"select":[0,0,1,1]}', SelectTarget((0.0, 0.0, 1.0, 1.0))),
        (b' {"select": [-5, 3.5, 20, 40.25]} ', SelectTarget((-5.0, 3.5, 20.0, 40.25))),
        (
            b'{"select": [0, 0, 1, 1], "ts": 1796428800.25}',
            SelectTarget((0.0, 0.0, 1.0, 1.0), 1796428800.25),
        ),
        (
            b'{"ts": 1796428800, "select": [0, 0, 1, 1]}',
            SelectTarget((0.0, 0.0, 1.0, 1.0), 1796428800.0),
        ),
    ],
)
def test_parse_ptz_accepts(payload: bytes, expected: object) -> None:
    assert parse_ptz(TOPIC, payload) == expected


@pytest.mark.parametrize(
    "payload",
    [
        b"",
        b"   ",
        b"MOVE",
        b"preset_",
        b"preset_256",
        b"preset_-1",
        b"preset_1 2",
        b"STOPP",
        b"\xff",
        b"STOP\x1b[2J",
        b"[1, 2, 3, 4]",
        b'{"select": "1,2,3,4"}',
        b'{"select": [1, 2, 3, -4]}',
        b'{"select": [1, 2, Infinity, 4]}',
        b'{"select": [1, 2, 3, 1' + b"0" * 500 + b"]}",
        b'{"SELECT": [1, 2, 3, 4]}',
        b'{"select": [1, 2, 3, 4], "ts": "now"}',
        b'{"select": [1, 2, 3, 4], "ts": -1}',
        b'{"select": [1, 2, 3, 4], "ts": 0}',
        b'{"select": [1, 2, 3, 4], "ts": NaN}',
        b'{"select": [1, 2, 3, 4], "ts": Infinity}',
        b'{"select": [1, 2, 3, 4], "ts": true}',
        b'{"select": [1, 2, 3, 4], "ts": 1' + b"0" * 400 + b"}",
        b'{"select": [1, 2, 3, 4], "ts": 1796428800, "id": 3}',
        b'{"ts": 1796428800}',
        b"{" * 600,
    ],
)
def test_parse_ptz_rejects_with_reason(payload: bytes) -> None:
    with pytest.raises(CommandError) as info:
        parse_ptz(TOPIC, payload)
    assert info.value.topic == TOPIC
    assert info.value.reason
    assert info.value.payload_size == len(payload)


def test_oversized_is_rejected_before_decoding() -> None:
    with pytest.raises(CommandError, match="too large"):
        parse_ptz(TOPIC, b"STOP" + b" " * 2000, max_bytes=1024)
    assert parse_ptz(TOPIC, b"STOP" + b" " * 1000, max_bytes=1024) == Stop()


@given(st.binary(max_size=2048))
def test_parsers_never_raise_anything_but_command_error(payload: bytes) -> None:
    for parse in (parse_ptz, parse_autotrack):
        try:
            parse(TOPIC, payload)
        except CommandError as exc:
            body = json.loads(exc.to_payload(0.0))
            assert len(body["payload_preview"]) <= 67


@pytest.mark.parametrize("word", [b"ON", b"on", b"On", b" oN\r\n"])
def test_autotrack_on(word: bytes) -> None:
    assert parse_autotrack("t", word) == SetAutotrack(True)


@pytest.mark.parametrize("word", [b"OFF", b"off", b"oFf"])
def test_autotrack_off(word: bytes) -> None:
    assert parse_autotrack("t", word) == SetAutotrack(False)


@pytest.mark.parametrize("word", [b"1", b"true", b"ONN", b"", b"\x00"])
def test_autotrack_rejects(word: bytes) -> None:
    with pytest.raises(CommandError):
        parse_autotrack("t", word)


def test_track_payload_shape_and_normalisation() -> None:
    msg = TrackMessage(
        ts=12.5,
        state=TrackState.OCCLUDED,
        frame_size=(800, 600),
        id=3,
        bbox=(400.0, 300.0, 80.0, 60.0),
        confidence=0.4567,
        velocity=(1.0, 2.0),
    )
    body = json.loads(msg.to_payload())
    assert body == {
        "ts": 12.5,
        "state": "occluded",
        "id": 3,
        "bbox": [400.0, 300.0, 80.0, 60.0],
        "bbox_norm": [0.5, 0.5, 0.1, 0.1],
        "confidence": 0.457,
        "velocity": [1.0, 2.0],
        "frame_size": [800, 600],
        "tracker": None,
    }
    night = TrackMessage(ts=0, state="tracking", frame_size=(640, 480), tracker="rf")
    assert json.loads(night.to_payload())["tracker"] == "rf"
    searching = json.loads(
        TrackMessage(ts=0, state=TrackState.SEARCHING, frame_size=(640, 480)).to_payload()
    )
    assert searching["bbox"] is None and searching["bbox_norm"] is None
    assert searching["id"] is None and searching["velocity"] is None


def test_track_state_accepts_another_str_enum_with_the_same_values() -> None:
    class OtherState(StrEnum):
        OCCLUDED = "occluded"

    msg = TrackMessage(ts=0, state=OtherState.OCCLUDED, frame_size=(10, 10))
    assert msg.state is TrackState.OCCLUDED
    assert json.loads(msg.to_payload())["state"] == "occluded"
    with pytest.raises(ValueError, match="not one of"):
        TrackMessage(ts=0, state="dancing", frame_size=(10, 10))


def test_ptz_state_payload() -> None:
    assert json.loads(PtzState(pan=64, tilt=-10, zoom=-1).to_payload()) == {
        "pan": 64,
        "tilt": -10,
        "zoom": "out",
        "source": "auto",
    }


# ---------------------------------------------------------------- config


def test_url_parsing() -> None:
    assert parse_broker_url("mqtt://broker").port == 1883
    tls = parse_broker_url("mqtts://broker.lan:8884")
    assert (tls.host, tls.port, tls.tls) == ("broker.lan", 8884, True)
    for bad in ("http://x", "mqtt://", "mqtt://u:p@host", "mqtt://h:99999", "mqtt://h/path"):
        with pytest.raises(ValueError):
            parse_broker_url(bad)


def test_config_from_url_for_sim_flag() -> None:
    cfg = mqtt_config_from_url("mqtt://127.0.0.1:1884")
    assert cfg.enabled and cfg.broker.port == 1884 and cfg.prefix == "ptzd"
    with pytest.raises(ConfigError) as info:
        mqtt_config_from_url("tcp://127.0.0.1:1884")
    assert info.value.problems[0][0] == "mqtt"
    assert "scheme" in info.value.problems[0][1]
    assert info.value.source == "--mqtt-url"


@pytest.mark.parametrize(
    ("overrides", "fragment"),
    [
        ({"reconnect_min_s": 10.0, "reconnect_max_s": 1.0}, "reconnect_min_s"),
        ({"url": "mqtts://h", "cert_file": "/c.pem"}, "cert_file and key_file"),
        ({"ca_file": "/ca.pem"}, "mqtts"),
        ({"password": "x"}, "without username"),
        ({"url": "ftp://h"}, "scheme"),
    ],
)
def test_cross_field_validation(overrides: dict[str, object], fragment: str) -> None:
    with pytest.raises(ValidationError, match=fragment):
        MqttConfig.model_validate(overrides)


@pytest.mark.parametrize(
    ("key", "value"),
    [
        ("track_rate_hz", 0),
        ("track_rate_hz", 5000),
        ("keepalive_s", 1),
        ("max_payload_bytes", 10),
        ("command_queue_size", 0),
        ("prefix", "a/#"),
        ("prefix", "/lead"),
        ("client_id", "has space"),
        ("bogus", 1),
    ],
)
def test_bounds_name_the_key(key: str, value: object) -> None:
    with pytest.raises(ConfigError) as info:
        validate_config({"mqtt": {key: value}}, environ={})
    assert info.value.problems[0][0] == f"mqtt.{key}"


def test_password_from_env_is_masked_everywhere() -> None:
    env = {"PTZD_MQTT__USERNAME": "ptzd", "PTZD_MQTT__PASSWORD": "hunter2"}
    config = validate_config({}, environ=env)
    assert isinstance(config.mqtt.password, SecretStr)
    assert config.mqtt.password.get_secret_value() == "hunter2"
    assert "hunter2" not in to_toml(config)
    assert "hunter2" not in repr(config) and "hunter2" not in str(config.mqtt)
    assert resolve_password(config.mqtt, {}) == config.mqtt.password


@pytest.mark.parametrize(
    ("section", "env"),
    [
        ({"url": "ftp://x"}, {"PTZD_MQTT__PASSWORD": "hunter2"}),  # table-level error
        ({"username": "u"}, {"PTZD_MQTT__PASSWORD": "[7, 7]"}),  # field-level error
    ],
)
def test_validation_errors_never_echo_the_password(
    section: dict[str, object], env: dict[str, str]
) -> None:
    with pytest.raises(ConfigError) as info:
        validate_config({"mqtt": section}, environ=env)
    text = repr(info.value.problems) + str(info.value)
    assert "hunter2" not in text and "[7, 7]" not in text and "7, 7" not in text


def test_check_config_never_prints_the_password(tmp_path: Path) -> None:
    cfg = tmp_path / "c.toml"
    cfg.write_text('[mqtt]\nusername = "ptzd"\n')
    env = {"PTZD_MQTT__PASSWORD": "hunter2", "PATH": "/usr/bin:/bin"}
    out = subprocess.run(
        [sys.executable, "-m", "ptzd", "check-config", str(cfg)],
        capture_output=True,
        text=True,
        env=env,
        timeout=60,
    )
    assert out.returncode == 0, out.stderr
    assert "hunter2" not in out.stdout + out.stderr
    assert 'password = "**********"' in out.stdout


def test_password_from_systemd_credential(tmp_path: Path) -> None:
    cfg = MqttConfig(username="ptzd")
    assert resolve_password(cfg, {}) is None
    assert resolve_password(cfg, {"CREDENTIALS_DIRECTORY": str(tmp_path)}) is None  # absent
    (tmp_path / "mqtt-password").write_text("pa ss\n")
    secret = resolve_password(cfg, {"CREDENTIALS_DIRECTORY": str(tmp_path)})
    assert secret is not None and secret.get_secret_value() == "pa ss"
    (tmp_path / "other").write_bytes(b"\xff\xfe")
    with pytest.raises(ConfigError) as info:
        resolve_password(
            MqttConfig(username="u", password_credential="other"),
            {"CREDENTIALS_DIRECTORY": str(tmp_path)},
        )
    assert info.value.problems[0][0] == "mqtt.password_credential"


def test_shipped_defaults() -> None:
    assert Config().mqtt.track_rate_hz == 10.0
    assert Config().mqtt.enabled is False


# ---------------------------------------------------------------- backoff


def test_backoff_grows_is_capped_and_jittered() -> None:
    rng = random.Random(1)
    delays = [backoff_delay(n, 0.5, 30.0, rng) for n in range(12)]
    for n, d in enumerate(delays):
        cap = min(30.0, 0.5 * 2**n)
        assert cap / 2 <= d <= cap
    assert delays[-1] >= 15.0
    again = [backoff_delay(n, 0.5, 30.0, random.Random(1)) for n in range(1)]
    assert again[0] == delays[0]  # seeded: repeatable
    spread = {round(backoff_delay(5, 0.5, 30.0, rng), 6) for _ in range(20)}
    assert len(spread) > 10  # two daemons do not retry in lockstep
    assert backoff_delay(10_000, 0.5, 30.0, rng) <= 30.0


def test_bridge_constructor_does_no_io() -> None:
    # No event loop, no broker: constructing must still work (I/O happens in __aenter__).
    bridge = MqttBridge(MqttConfig(enabled=True), "cam9")
    bridge.publish_track(TrackMessage(ts=0, state=TrackState.LOST, frame_size=(1, 1)))
    bridge.set_zoom_layer(1)
    assert bridge.stats.dropped_disconnected == 1
    assert not bridge.connected
