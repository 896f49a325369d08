"""Pelco-P and Pelco-D frames: typed commands to bytes and back. Pure: no I/O, no clock.

Pelco-P (8 bytes): ``A0 addr d1 d2 d3 d4 AF cksum``; cksum = XOR of bytes 1-7 (STX and ETX
included); the wire address is the camera's address minus one (the Pelco P document numbers
the first camera $00). Pelco-D (7 bytes): ``FF addr c1 c2 d1 d2 cksum``; cksum = (addr + c1 +
c2 + d1 + d2) mod 256; the address is on the wire as is. docs/protocol.md has the bit tables
and the sources.

Everything that is checked is checked when a command is built: ``Motion(pan=99)`` raises
`CommandValueError`; nothing is clamped. `decode` raises `FrameError` for bytes that are not
one valid frame. A checksum-valid frame whose payload is not one of the modelled commands
decodes to `OtherCommand`, so no valid frame is ever lost.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from enum import IntEnum, StrEnum

from ptzd.errors import PtzdError

P_STX = 0xA0
P_ETX = 0xAF
P_LENGTH = 8
D_SYNC = 0xFF
D_LENGTH = 7

MAX_SPEED = 63  # 0x3F
TURBO = 64  # pan only; Pelco-P sends 0x40, Pelco-D sends 0xFF
D_TURBO_BYTE = 0xFF
MAX_PRESET = 255
MAX_ZOOM_SPEED = 3
MAX_ANGLE = 35999  # hundredths of a degree
MAX_WORD = 0xFFFF

# Bits of the command bytes. Pelco-P: d1 and d2 (the Pelco P document). Pelco-D: c1 and c2.
_P_D1_FOCUS_FAR = 0x01
_P_D1_FOCUS_NEAR = 0x02
_P_D1_IRIS_OPEN = 0x04
_P_D1_IRIS_CLOSE = 0x08
_D_C1_FOCUS_NEAR = 0x01
_D_C1_IRIS_OPEN = 0x02
_D_C1_IRIS_CLOSE = 0x04
_D_C2_FOCUS_FAR = 0x80
# shared by Pelco-P d2 and Pelco-D c2
_EXTENDED = 0x01
_PAN_RIGHT = 0x02
_PAN_LEFT = 0x04
_TILT_UP = 0x08
_TILT_DOWN = 0x10
_ZOOM_TELE = 0x20
_ZOOM_WIDE = 0x40
_DIRECTION_BITS = _PAN_RIGHT | _PAN_LEFT | _TILT_UP | _TILT_DOWN | _ZOOM_TELE | _ZOOM_WIDE

# Extended opcodes (the whole second command byte, bit 0 set), both protocols.
_OP_PRESET = {0x03: "SET", 0x05: "CLEAR", 0x07: "GOTO"}
_OP_ZOOM_SPEED = 0x25
# Pelco-D only
_OP_ABSOLUTE = {0x4B: "PAN", 0x4D: "TILT", 0x4F: "ZOOM"}
_OP_QUERY = {0x51: "PAN", 0x53: "TILT", 0x55: "ZOOM"}
_OP_REPLY = {0x59: "PAN", 0x5B: "TILT", 0x5D: "ZOOM"}


class CommandValueError(PtzdError, ValueError):
    """A command or address field outside its allowed range (never clamped)."""

    def __init__(self, name: str, value: object, allowed: str) -> None:
        self.name = name
        self.value = value
        self.allowed = allowed
        super().__init__(f"{name} must be {allowed}, got {value!r}")


class FrameError(PtzdError, ValueError):
    """Bytes that are not one valid frame; `reason` says why, `raw` holds the bytes."""

    def __init__(self, raw: bytes, reason: str) -> None:
        self.raw = bytes(raw)
        self.reason = reason
        super().__init__(f"{reason}: {self.raw.hex(' ')}")


def _check(name: str, value: int, low: int, high: int) -> None:
    if isinstance(value, bool) or not isinstance(value, int) or not low <= value <= high:
        raise CommandValueError(name, value, f"an integer in {low}..{high}")


class PelcoProtocol(StrEnum):
    P = "p"
    D = "d"


class Zoom(IntEnum):
    OUT = -1  # wide
    NONE = 0
    IN = 1  # tele


class PresetAction(StrEnum):
    SET = "set"
    CLEAR = "clear"
    GOTO = "goto"


class Axis(StrEnum):
    PAN = "pan"
    TILT = "tilt"
    ZOOM = "zoom"


@dataclass(frozen=True, slots=True)
class Motion:
    """Continuous pan/tilt/zoom/focus/iris. `Motion()` is STOP.

    pan: -64..64 (< 0 left, 64 = turbo); tilt: -63..63 (> 0 up); focus: -1 near, 0, 1 far;
    iris: -1 close, 0, 1 open.
    """

    pan: int = 0
    tilt: int = 0
    zoom: Zoom = Zoom.NONE
    focus: int = 0
    iris: int = 0

    def __post_init__(self) -> None:
        _check("pan", self.pan, -TURBO, TURBO)
        _check("tilt", self.tilt, -MAX_SPEED, MAX_SPEED)
        zoom: object = self.zoom
        if not isinstance(zoom, Zoom):  # a plain int from a caller without type checks
            if zoom not in (-1, 0, 1) or isinstance(zoom, bool):
                raise CommandValueError("zoom", zoom, "-1, 0 or 1")
            object.__setattr__(self, "zoom", Zoom(zoom))
        _check("focus", self.focus, -1, 1)
        _check("iris", self.iris, -1, 1)

    @property
    def is_stop(self) -> bool:
        return self == STOP


STOP = Motion()


@dataclass(frozen=True, slots=True)
class Preset:
    action: PresetAction
    number: int  # 1..255

    def __post_init__(self) -> None:
        if not isinstance(self.action, PresetAction):
            raise CommandValueError("preset action", self.action, "set, clear or goto")
        _check("preset", self.number, 1, MAX_PRESET)


@dataclass(frozen=True, slots=True)
class ZoomSpeed:
    speed: int  # 0 (slowest) .. 3 (fastest)

    def __post_init__(self) -> None:
        _check("zoom speed", self.speed, 0, MAX_ZOOM_SPEED)


def _check_position(axis: Axis, value: int) -> None:
    if not isinstance(axis, Axis):
        raise CommandValueError("axis", axis, "pan, tilt or zoom")
    # pan/tilt in hundredths of a degree; zoom is a 16-bit magnification count
    _check(f"{axis} position", value, 0, MAX_WORD if axis == Axis.ZOOM else MAX_ANGLE)


@dataclass(frozen=True, slots=True)
class AbsolutePosition:
    """Pelco-D 0x4B/0x4D/0x4F: go to a position (pan/tilt 0..35999 hundredths of a degree)."""

    axis: Axis
    value: int

    def __post_init__(self) -> None:
        _check_position(self.axis, self.value)


@dataclass(frozen=True, slots=True)
class PositionQuery:
    """Pelco-D 0x51/0x53/0x55: ask the dome where an axis is."""

    axis: Axis

    def __post_init__(self) -> None:
        if not isinstance(self.axis, Axis):
            raise CommandValueError("axis", self.axis, "pan, tilt or zoom")


@dataclass(frozen=True, slots=True)
class PositionReply:
    """Pelco-D 0x59/0x5B/0x5D: the dome's answer to a `PositionQuery`."""

    axis: Axis
    value: int

    def __post_init__(self) -> None:
        _check_position(self.axis, self.value)


@dataclass(frozen=True, slots=True)
class OtherCommand:
    """A valid frame whose payload is none of the modelled commands (aux, camera on/off,
    autoscan, ...): the four payload bytes as they are on the wire (after the address)."""

    c1: int
    c2: int
    d1: int
    d2: int

    def __post_init__(self) -> None:
        for name in ("c1", "c2", "d1", "d2"):
            _check(name, getattr(self, name), 0, 0xFF)


Command = (
    Motion | Preset | ZoomSpeed | AbsolutePosition | PositionQuery | PositionReply | OtherCommand
)
D_ONLY = (AbsolutePosition, PositionQuery, PositionReply)


@dataclass(frozen=True, slots=True)
class Frame:
    protocol: PelcoProtocol
    address: int  # the camera's own address, 1-based
    command: Command
    raw: bytes = field(repr=False)


# --- encoding ----------------------------------------------------------------------------


def _invert(table: dict[int, str]) -> dict[str, int]:
    return {name: op for op, name in table.items()}


_PRESET_OP = _invert(_OP_PRESET)
_ABSOLUTE_OP = _invert(_OP_ABSOLUTE)
_QUERY_OP = _invert(_OP_QUERY)
_REPLY_OP = _invert(_OP_REPLY)


def _motion_payload(motion: Motion, protocol: PelcoProtocol) -> tuple[int, int, int, int]:
    c1 = 0
    c2 = 0
    if motion.pan > 0:
        c2 |= _PAN_RIGHT
    elif motion.pan < 0:
        c2 |= _PAN_LEFT
    if motion.tilt > 0:
        c2 |= _TILT_UP
    elif motion.tilt < 0:
        c2 |= _TILT_DOWN
    if motion.zoom == Zoom.IN:
        c2 |= _ZOOM_TELE
    elif motion.zoom == Zoom.OUT:
        c2 |= _ZOOM_WIDE
    if protocol == PelcoProtocol.P:
        c1 |= {1: _P_D1_FOCUS_FAR, -1: _P_D1_FOCUS_NEAR, 0: 0}[motion.focus]
        c1 |= {1: _P_D1_IRIS_OPEN, -1: _P_D1_IRIS_CLOSE, 0: 0}[motion.iris]
        pan_byte = abs(motion.pan)  # 0x40 is turbo
    else:
        c1 |= _D_C1_FOCUS_NEAR if motion.focus < 0 else 0
        c2 |= _D_C2_FOCUS_FAR if motion.focus > 0 else 0
        c1 |= {1: _D_C1_IRIS_OPEN, -1: _D_C1_IRIS_CLOSE, 0: 0}[motion.iris]
        pan_byte = D_TURBO_BYTE if abs(motion.pan) == TURBO else abs(motion.pan)
    return c1, c2, pan_byte, abs(motion.tilt)


def _payload(command: Command, protocol: PelcoProtocol) -> tuple[int, int, int, int]:
    if isinstance(command, Motion):
        return _motion_payload(command, protocol)
    if isinstance(command, Preset):
        return 0, _PRESET_OP[command.action.name], 0, command.number
    if isinstance(command, ZoomSpeed):
        return 0, _OP_ZOOM_SPEED, 0, command.speed
    if isinstance(command, OtherCommand):
        return command.c1, command.c2, command.d1, command.d2
    if protocol != PelcoProtocol.D:
        raise CommandValueError("protocol", str(protocol), f"d for {type(command).__name__}")
    if isinstance(command, PositionQuery):
        return 0, _QUERY_OP[command.axis.name], 0, 0
    table = _ABSOLUTE_OP if isinstance(command, AbsolutePosition) else _REPLY_OP
    return 0, table[command.axis.name], command.value >> 8, command.value & 0xFF


def encode(command: Command, *, protocol: PelcoProtocol, address: int) -> bytes:
    """The frame carrying `command` to the camera at `address` (1-based)."""
    protocol = PelcoProtocol(protocol)
    c1, c2, d1, d2 = _payload(command, protocol)
    if protocol == PelcoProtocol.P:
        _check("Pelco-P address", address, 1, 256)
        body = bytes((P_STX, address - 1, c1, c2, d1, d2, P_ETX))
        return body + bytes((_xor(body),))
    _check("Pelco-D address", address, 1, 255)
    body = bytes((D_SYNC, address, c1, c2, d1, d2))
    return body + bytes((sum(body[1:]) & 0xFF,))


def _xor(data: bytes) -> int:
    result = 0
    for byte in data:
        result ^= byte
    return result


# --- decoding ----------------------------------------------------------------------------


def _decode_motion(protocol: PelcoProtocol, c1: int, c2: int, d1: int, d2: int) -> Motion | None:
    """The `Motion` in a standard (non-extended) payload, or None if it holds other bits."""
    if protocol == PelcoProtocol.P:
        lens_bits = _P_D1_FOCUS_FAR | _P_D1_FOCUS_NEAR | _P_D1_IRIS_OPEN | _P_D1_IRIS_CLOSE
        if c1 & ~lens_bits or c2 & ~_DIRECTION_BITS:
            return None  # camera on/off, autoscan, reserved bits
        focus = _pair(c1 & _P_D1_FOCUS_FAR, c1 & _P_D1_FOCUS_NEAR)
        iris = _pair(c1 & _P_D1_IRIS_OPEN, c1 & _P_D1_IRIS_CLOSE)
        pan_speed = TURBO if d1 >= TURBO else d1
    else:
        lens_bits = _D_C1_FOCUS_NEAR | _D_C1_IRIS_OPEN | _D_C1_IRIS_CLOSE
        if c1 & ~lens_bits or c2 & ~(_DIRECTION_BITS | _D_C2_FOCUS_FAR):
            return None  # sense, scan, camera on/off
        focus = _pair(c2 & _D_C2_FOCUS_FAR, c1 & _D_C1_FOCUS_NEAR)
        iris = _pair(c1 & _D_C1_IRIS_OPEN, c1 & _D_C1_IRIS_CLOSE)
        pan_speed = TURBO if d1 >= TURBO else d1  # 0xFF on send; anything >= 0x40 is turbo
    pan = _pair(c2 & _PAN_RIGHT, c2 & _PAN_LEFT)
    tilt = _pair(c2 & _TILT_UP, c2 & _TILT_DOWN)
    zoom = _pair(c2 & _ZOOM_TELE, c2 & _ZOOM_WIDE)
    if None in (focus, iris, pan, tilt, zoom) or d2 > MAX_SPEED:
        return None  # contradictory directions or a tilt speed beyond 0x3F
    assert pan is not None and tilt is not None and zoom is not None
    assert focus is not None and iris is not None
    return Motion(pan=pan * pan_speed, tilt=tilt * d2, zoom=Zoom(zoom), focus=focus, iris=iris)


def _pair(plus: int, minus: int) -> int | None:
    """+1, -1 or 0 from two direction bits; None when both are set."""
    if plus and minus:
        return None
    return 1 if plus else -1 if minus else 0


def _decode_extended(protocol: PelcoProtocol, c2: int, d1: int, d2: int) -> Command | None:
    if c2 in _OP_PRESET and d1 == 0 and d2 >= 1:
        return Preset(PresetAction[_OP_PRESET[c2]], d2)
    if c2 == _OP_ZOOM_SPEED and d1 == 0 and d2 <= MAX_ZOOM_SPEED:
        return ZoomSpeed(d2)
    if protocol != PelcoProtocol.D:
        return None
    value = (d1 << 8) | d2
    try:
        if c2 in _OP_ABSOLUTE:
            return AbsolutePosition(Axis[_OP_ABSOLUTE[c2]], value)
        if c2 in _OP_QUERY and value == 0:
            return PositionQuery(Axis[_OP_QUERY[c2]])
        if c2 in _OP_REPLY:
            return PositionReply(Axis[_OP_REPLY[c2]], value)
    except CommandValueError:
        return None  # a position beyond 35999: keep the frame as OtherCommand
    return None


def _decode_payload(protocol: PelcoProtocol, c1: int, c2: int, d1: int, d2: int) -> Command:
    command: Command | None
    if c2 & _EXTENDED:
        command = _decode_extended(protocol, c2, d1, d2) if c1 == 0 else None
    else:
        command = _decode_motion(protocol, c1, c2, d1, d2)
    return command if command is not None else OtherCommand(c1, c2, d1, d2)


def decode(raw: bytes) -> Frame:
    """The one complete frame in `raw`; raises `FrameError` otherwise."""
    raw = bytes(raw)
    if not raw:
        raise FrameError(raw, "empty")
    if raw[0] == P_STX:
        if len(raw) != P_LENGTH:
            raise FrameError(raw, f"Pelco-P frame must be {P_LENGTH} bytes, got {len(raw)}")
        if raw[6] != P_ETX:
            raise FrameError(raw, f"Pelco-P ETX must be 0xaf, got {raw[6]:#04x}")
        if _xor(raw[:7]) != raw[7]:
            expected = _xor(raw[:7])
            raise FrameError(raw, f"bad Pelco-P checksum {raw[7]:#04x}, expected {expected:#04x}")
        command = _decode_payload(PelcoProtocol.P, raw[2], raw[3], raw[4], raw[5])
        return Frame(PelcoProtocol.P, raw[1] + 1, command, raw)
    if raw[0] == D_SYNC:
        if len(raw) != D_LENGTH:
            raise FrameError(raw, f"Pelco-D frame must be {D_LENGTH} bytes, got {len(raw)}")
        expected = sum(raw[1:6]) & 0xFF
        if expected != raw[6]:
            raise FrameError(raw, f"bad Pelco-D checksum {raw[6]:#04x}, expected {expected:#04x}")
        if raw[1] == 0:
            raise FrameError(raw, "Pelco-D address 0 is not a camera address")
        command = _decode_payload(PelcoProtocol.D, raw[2], raw[3], raw[4], raw[5])
        return Frame(PelcoProtocol.D, raw[1], command, raw)
    raise FrameError(raw, f"first byte must be 0xa0 (Pelco-P) or 0xff (Pelco-D), got {raw[0]:#04x}")


class FrameParser:
    """Incremental decoder for a byte stream carrying Pelco-P and Pelco-D frames, mixed.

    `feed` returns the frames completed by the new bytes; it works fed one byte at a time.
    After garbage or a corrupted frame it resynchronises on the next 0xA0/0xFF that starts a
    valid frame. Counters: `frames` decoded, `garbage_bytes` skipped (every byte that was not
    part of a valid frame, corrupted frames included), `bad_checksums` (candidate frames with
    the right shape but a wrong checksum), `rejected_frames` (checksum-valid Pelco-D frames
    for address 0, skipped whole).
    """

    def __init__(self) -> None:
        self._buffer = bytearray()
        self.frames = 0
        self.garbage_bytes = 0
        self.bad_checksums = 0
        self.rejected_frames = 0

    @property
    def pending(self) -> int:
        """Bytes held while waiting for the rest of a possible frame."""
        return len(self._buffer)

    def feed(self, data: bytes) -> list[Frame]:
        self._buffer += data
        found: list[Frame] = []
        buffer = self._buffer
        while buffer:
            start = _next_sync(buffer)
            if start < 0:
                self.garbage_bytes += len(buffer)
                buffer.clear()
                break
            if start > 0:
                self.garbage_bytes += start
                del buffer[:start]
            length = P_LENGTH if buffer[0] == P_STX else D_LENGTH
            if len(buffer) < length:
                break  # wait for the rest
            candidate = bytes(buffer[:length])
            try:
                frame = decode(candidate)
            except FrameError as exc:
                if exc.reason.startswith("Pelco-D address 0"):
                    self.rejected_frames += 1
                    self.garbage_bytes += length
                    del buffer[:length]
                    continue
                if "checksum" in exc.reason:
                    self.bad_checksums += 1
                self.garbage_bytes += 1
                del buffer[:1]  # not a frame start after all: look again from the next byte
                continue
            del buffer[:length]
            self.frames += 1
            found.append(frame)
        return found


def _next_sync(buffer: bytearray) -> int:
    """Index of the first 0xA0 or 0xFF in `buffer`, or -1."""
    p = buffer.find(P_STX)
    d = buffer.find(D_SYNC)
    if p < 0:
        return d
    if d < 0:
        return p
    return min(p, d)


def frame_to_dict(frame: Frame) -> dict[str, object]:
    """A decoded frame as JSON-ready data: protocol, address, command name, its fields, hex."""
    command = frame.command
    fields: dict[str, object] = {}
    for name in command.__dataclass_fields__:
        value = getattr(command, name)
        if isinstance(value, Zoom):
            value = value.name.lower()
        elif isinstance(value, StrEnum):
            value = str(value)
        fields[name] = value
    kind = {
        Motion: "motion",
        Preset: "preset",
        ZoomSpeed: "zoom_speed",
        AbsolutePosition: "absolute_position",
        PositionQuery: "position_query",
        PositionReply: "position_reply",
        OtherCommand: "other",
    }[type(command)]
    return {
        "protocol": str(frame.protocol),
        "address": frame.address,
        "command": kind,
        **fields,
        "hex": frame.raw.hex(" "),
    }
