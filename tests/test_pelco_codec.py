"""Pelco-P/D codec: byte vectors from the Pelco P document, round trips, resync."""

from __future__ import annotations

import pytest
from hypothesis import given
from hypothesis import strategies as st

from ptzd.pelco.codec import (
    AbsolutePosition,
    Axis,
    Command,
    CommandValueError,
    Frame,
    FrameError,
    FrameParser,
    Motion,
    OtherCommand,
    PelcoProtocol,
    PositionQuery,
    PositionReply,
    Preset,
    PresetAction,
    Zoom,
    ZoomSpeed,
    decode,
    encode,
)

P, D = PelcoProtocol.P, PelcoProtocol.D


def h(text: str) -> bytes:
    return bytes.fromhex(text)


@pytest.mark.parametrize(
    ("command", "protocol", "wire"),
    [
        (Motion(pan=-0x20), P, "a0 00 00 04 20 00 af 2b"),  # pan left, Pelco P document
        (Motion(pan=0x20), P, "a0 00 00 02 20 00 af 2d"),  # pan right
        (Motion(tilt=0x20), P, "a0 00 00 08 00 20 af 27"),  # tilt up
        (Motion(), P, "a0 00 00 00 00 00 af 0f"),  # stop
        (Motion(pan=-0x20), D, "ff 01 00 04 20 00 25"),
        (Motion(pan=64), P, "a0 00 00 02 40 00 af 4d"),  # Pelco-P turbo 0x40
        (Motion(pan=-64), D, "ff 01 00 04 ff 00 04"),  # Pelco-D turbo 0xff
        (Motion(tilt=-10), D, "ff 01 00 10 00 0a 1b"),
        (Motion(zoom=Zoom.IN), P, "a0 00 00 20 00 00 af 2f"),  # tele = d2 bit 5
        (Motion(zoom=Zoom.OUT), P, "a0 00 00 40 00 00 af 4f"),  # wide = d2 bit 6
        # focus/iris live in d1 in Pelco-P (not the Pelco-D layout)
        (Motion(focus=1), P, "a0 00 01 00 00 00 af 0e"),
        (Motion(focus=-1), P, "a0 00 02 00 00 00 af 0d"),
        (Motion(iris=1), P, "a0 00 04 00 00 00 af 0b"),
        (Motion(iris=-1), P, "a0 00 08 00 00 00 af 07"),
        (Motion(focus=1), D, "ff 01 00 80 00 00 81"),  # Pelco-D focus far = c2 bit 7
        (Motion(focus=-1), D, "ff 01 01 00 00 00 02"),
        (Preset(PresetAction.SET, 3), P, "a0 00 00 03 00 03 af 0f"),
        (Preset(PresetAction.CLEAR, 3), D, "ff 01 00 05 00 03 09"),
        (Preset(PresetAction.GOTO, 255), D, "ff 01 00 07 00 ff 07"),
        (ZoomSpeed(2), P, "a0 00 00 25 00 02 af 28"),
        (AbsolutePosition(Axis.PAN, 9000), D, "ff 01 00 4b 23 28 97"),
        (PositionQuery(Axis.TILT), D, "ff 01 00 53 00 00 54"),
        (PositionReply(Axis.ZOOM, 0x1234), D, "ff 01 00 5d 12 34 a4"),
    ],
)
def test_byte_vectors(command: Command, protocol: PelcoProtocol, wire: str) -> None:
    assert encode(command, protocol=protocol, address=1) == h(wire)
    frame = decode(h(wire))
    assert frame == Frame(protocol, 1, command, h(wire))


def test_address_convention() -> None:
    # Pelco-P puts address - 1 on the wire (the document's first camera is $00); D as is
    assert encode(Motion(), protocol=P, address=256)[1] == 0xFF
    assert encode(Motion(), protocol=D, address=7)[1] == 7
    assert decode(encode(Motion(), protocol=P, address=5)).address == 5


@pytest.mark.parametrize(
    "build",
    [
        lambda: Motion(pan=65),
        lambda: Motion(tilt=64),
        lambda: Motion(tilt=-64),
        lambda: Motion(focus=2),
        lambda: Motion(zoom=2),  # type: ignore[arg-type]
        lambda: Preset(PresetAction.GOTO, 0),
        lambda: Preset(PresetAction.SET, 256),
        lambda: ZoomSpeed(4),
        lambda: AbsolutePosition(Axis.PAN, 36000),
        lambda: encode(Motion(), protocol=P, address=0),
        lambda: encode(Motion(), protocol=P, address=257),
        lambda: encode(Motion(), protocol=D, address=256),
        lambda: encode(PositionQuery(Axis.PAN), protocol=P, address=1),  # Pelco-D only
    ],
)
def test_invalid_values_raise_never_clamp(build: object) -> None:
    with pytest.raises(CommandValueError) as info:
        build()  # type: ignore[operator]
    assert "must be" in str(info.value)


@pytest.mark.parametrize(
    ("wire", "reason"),
    [
        ("a0 00 00 04 20 00 af 2c", "checksum"),
        ("ff 01 00 04 20 00 26", "checksum"),
        ("a0 00 00 04 20 00 ae 2a", "ETX"),
        ("a0 00 00 04 20 00 af", "8 bytes"),
        ("ff 00 00 04 20 00 24", "address 0"),
        ("12 34", "first byte"),
    ],
)
def test_decode_rejects(wire: str, reason: str) -> None:
    with pytest.raises(FrameError) as info:
        decode(h(wire))
    assert reason in info.value.reason
    assert info.value.raw == h(wire)


def test_unmodelled_frames_are_kept_as_other_commands() -> None:
    camera_on = decode(h("a0 00 50 00 00 00 af 5f"))  # Pelco-P camera on (d1 bits 4 and 6)
    assert camera_on.command == OtherCommand(0x50, 0, 0, 0)
    aux = decode(encode(OtherCommand(0, 0x09, 0, 1), protocol=D, address=3))  # aux on
    assert aux.command == OtherCommand(0, 0x09, 0, 1)
    both_ways = decode(encode(OtherCommand(0, 0x06, 0x10, 0), protocol=P, address=1))
    assert isinstance(both_ways.command, OtherCommand)  # left and right at once


def test_pelco_d_decoder_takes_any_pan_byte_from_0x40_as_turbo() -> None:
    assert decode(h("ff 01 00 02 40 00 43")).command == Motion(pan=64)
    assert decode(h("ff 01 00 02 9c 00 9f")).command == Motion(pan=64)


# --- round trips -------------------------------------------------------------------------

motions = st.builds(
    Motion,
    pan=st.integers(-64, 64),
    tilt=st.integers(-63, 63),
    zoom=st.sampled_from(Zoom),
    focus=st.integers(-1, 1),
    iris=st.integers(-1, 1),
)
common = st.one_of(
    motions,
    st.builds(Preset, st.sampled_from(PresetAction), st.integers(1, 255)),
    st.builds(ZoomSpeed, st.integers(0, 3)),
)
d_only = st.one_of(
    st.builds(
        AbsolutePosition,
        st.sampled_from([Axis.PAN, Axis.TILT]),
        st.integers(0, 35999),
    ),
    st.builds(AbsolutePosition, st.just(Axis.ZOOM), st.integers(0, 0xFFFF)),
    st.builds(PositionQuery, st.sampled_from(Axis)),
    st.builds(PositionReply, st.sampled_from([Axis.PAN, Axis.TILT]), st.integers(0, 35999)),
    st.builds(PositionReply, st.just(Axis.ZOOM), st.integers(0, 0xFFFF)),
)
frames = st.one_of(
    st.tuples(st.just(P), st.integers(1, 256), common),
    st.tuples(st.just(D), st.integers(1, 255), st.one_of(common, d_only)),
)


@given(frames)
def test_round_trip_every_command(case: tuple[PelcoProtocol, int, Command]) -> None:
    protocol, address, command = case
    raw = encode(command, protocol=protocol, address=address)
    assert len(raw) == (8 if protocol == P else 7)
    assert decode(raw) == Frame(protocol, address, command, raw)


@given(st.binary(min_size=7, max_size=8))
def test_decode_never_loses_a_valid_frame(raw: bytes) -> None:
    """Any checksum-valid frame decodes, and encoding its command gives the same bytes back
    unless it was a lossy motion (a direction bit with speed 0)."""
    try:
        frame = decode(raw)
    except FrameError:
        return
    again = encode(frame.command, protocol=frame.protocol, address=frame.address)
    assert decode(again).command == frame.command


@given(st.lists(frames, min_size=1, max_size=12), st.data())
def test_parser_resyncs_after_garbage_and_bad_checksums(
    cases: list[tuple[PelcoProtocol, int, Command]], data: st.DataObject
) -> None:
    stream = bytearray()
    sent: list[Frame] = []
    for protocol, address, command in cases:
        raw = encode(command, protocol=protocol, address=address)
        # garbage between frames: no sync bytes, so it can never start a frame
        junk = data.draw(st.binary(max_size=6).map(lambda b: bytes(x & 0x7F for x in b)))
        stream += junk
        if data.draw(st.booleans()):  # a corrupted copy first: wrong checksum
            stream += raw[:-1] + bytes([raw[-1] ^ 0x01])
        stream += raw
        sent.append(Frame(protocol, address, command, raw))
    whole = FrameParser().feed(bytes(stream))
    assert whole == sent
    parser = FrameParser()
    one_by_one = [f for byte in stream for f in parser.feed(bytes([byte]))]
    assert one_by_one == sent
    assert parser.frames == len(sent)
    assert parser.garbage_bytes == len(stream) - sum(len(f.raw) for f in sent)
    assert parser.pending == 0


def test_parser_counts_bad_checksums_and_mixed_protocols_byte_by_byte() -> None:
    good_p = encode(Motion(pan=-32), protocol=P, address=1)
    good_d = encode(Preset(PresetAction.GOTO, 9), protocol=D, address=2)
    bad_p = good_p[:-1] + b"\x00"
    stream = b"\x00\x13" + bad_p + good_d + b"\xa0\xaf" + good_p + b"\xff"
    parser = FrameParser()
    out: list[Frame] = []
    for byte in stream:
        out += parser.feed(bytes([byte]))
    assert [f.command for f in out] == [Preset(PresetAction.GOTO, 9), Motion(pan=-32)]
    assert parser.bad_checksums == 1
    assert parser.pending == 1  # the trailing 0xff may still become a frame
    assert parser.garbage_bytes == 2 + 8 + 2
