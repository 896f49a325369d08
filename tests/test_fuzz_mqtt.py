"""Hypothesis fuzzing of MQTT command payloads: only `CommandError` may come out."""

from __future__ import annotations

import json

from hypothesis import given, settings
from hypothesis import strategies as st

from ptzd.mqtt.messages import CommandError, GotoPreset, SelectTarget, parse_autotrack, parse_ptz

TOPIC = "ptzd/cam1/ptz"
FUZZ = settings(max_examples=200, deadline=None, derandomize=True)

words = st.sampled_from(
    ["STOP", "MOVE_LEFT", "zoom_in", "preset_1", "preset_0", "preset_256", "ON", "off", "{", "}"]
)
json_values = st.recursive(
    st.none() | st.booleans() | st.integers() | st.floats() | st.text(max_size=8),
    lambda inner: st.lists(inner, max_size=5) | st.dictionaries(st.text(max_size=6), inner),
    max_leaves=12,
)
payloads = (
    st.binary(max_size=2000)
    | st.text(max_size=300).map(str.encode)
    | st.tuples(words, st.text(max_size=5)).map(lambda t: (t[0] + t[1]).encode())
    | json_values.map(lambda v: json.dumps({"select": v}).encode())
    | json_values.map(lambda v: json.dumps({"select": [1, 2, 3, 4], "ts": v}).encode())
    | json_values.map(lambda v: json.dumps(v).encode())
)


@FUZZ
@given(payload=payloads)
def test_parse_ptz_raises_only_command_error(payload: bytes) -> None:
    try:
        command = parse_ptz(TOPIC, payload)
    except CommandError as exc:
        assert exc.reason  # a logged reason, never empty
        return
    if isinstance(command, SelectTarget):
        _, _, w, h = command.bbox
        assert w > 0 and h > 0
        assert all(abs(v) <= 100_000 for v in command.bbox)
        assert command.ts is None or 0 < command.ts <= 1e11  # finite seconds since the epoch
    if isinstance(command, GotoPreset):
        assert 1 <= command.number <= 255


@FUZZ
@given(payload=payloads)
def test_parse_autotrack_raises_only_command_error(payload: bytes) -> None:
    try:
        command = parse_autotrack(TOPIC, payload)
    except CommandError:
        return
    assert payload.strip().upper() in (b"ON", b"OFF")
    assert command.enabled == (payload.strip().upper() == b"ON")


@FUZZ
@given(box=st.lists(st.floats(allow_nan=True, allow_infinity=True), min_size=4, max_size=4))
def test_select_never_accepts_non_finite_or_empty_boxes(box: list[float]) -> None:
    # NaN and Infinity are not JSON, but json.loads takes them: they must still be refused
    text = json.dumps({"select": box})
    try:
        command = parse_ptz(TOPIC, text.encode())
    except CommandError:
        return
    assert isinstance(command, SelectTarget)
    assert all(abs(v) <= 100_000 for v in command.bbox)
    assert command.bbox[2] > 0 and command.bbox[3] > 0
