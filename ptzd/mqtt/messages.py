"""Topic names, outgoing payloads and incoming commands of the MQTT interface.

Pure: no I/O, no clock. The bridge (`ptzd.mqtt.bridge`) moves these over the wire;
`docs/mqtt.md` documents every topic. Topic names are a contract
(/work/shared/interfaces.md): `<prefix>/<camera>/...`.
"""

from __future__ import annotations

import json
import re
from dataclasses import dataclass
from enum import StrEnum
from typing import Any

from ptzd.errors import PtzdError


@dataclass(frozen=True)
class Topics:
    """Every topic of one camera under one prefix."""

    prefix: str
    camera: str

    @property
    def base(self) -> str:
        return f"{self.prefix}/{self.camera}"

    @property
    def availability(self) -> str:
        return f"{self.base}/availability"

    @property
    def track(self) -> str:
        return f"{self.base}/track"

    @property
    def zoom_layer(self) -> str:
        return f"{self.base}/zoom_layer"

    @property
    def ptz(self) -> str:
        return f"{self.base}/ptz"

    @property
    def ptz_state(self) -> str:
        return f"{self.base}/ptz/state"

    @property
    def autotrack_set(self) -> str:
        return f"{self.base}/autotrack/set"

    @property
    def autotrack_state(self) -> str:
        return f"{self.base}/autotrack/state"

    @property
    def error(self) -> str:
        return f"{self.base}/error"


ONLINE = b"online"
OFFLINE = b"offline"


# ---------------------------------------------------------------- outgoing


class TrackState(StrEnum):
    SEARCHING = "searching"
    TRACKING = "tracking"
    OCCLUDED = "occluded"
    LOST = "lost"


BBox = tuple[float, float, float, float]


@dataclass(frozen=True)
class TrackMessage:
    """What the tracker sees in one frame. `bbox` is in view pixels (x, y, w, h);
    `velocity` is the target's image velocity in view pixels per second (vx, vy);
    `ts` is seconds since the Unix epoch of the frame. `state` takes a `TrackState` or its
    string value, so the tracker's own state enum (a `StrEnum` with the same values) can be
    passed as is."""

    ts: float
    state: TrackState | str
    frame_size: tuple[int, int]
    id: int | None = None
    bbox: BBox | None = None
    confidence: float | None = None
    velocity: tuple[float, float] | None = None
    # acquisition state changes since the previous message (`Transition.to_dict()`):
    # {"t", "from", "state", "reason", "bbox"}; the key is left out when there are none
    transitions: tuple[dict[str, Any], ...] = ()
    # the likelihood that made `bbox` (`color`, `rf`, `svm`; with `auto`, the day or the
    # night one running now), or None
    tracker: str | None = None

    def __post_init__(self) -> None:
        try:
            state = TrackState(str(self.state))
        except ValueError:
            allowed = ", ".join(t.value for t in TrackState)
            raise ValueError(f"track state {self.state!r} is not one of {allowed}") from None
        object.__setattr__(self, "state", state)

    def bbox_norm(self) -> BBox | None:
        """`bbox` divided by the frame size: resolution-independent, in [0, 1] when inside."""
        if self.bbox is None:
            return None
        width, height = self.frame_size
        x, y, w, h = self.bbox
        return (x / width, y / height, w / width, h / height)

    def to_payload(self) -> bytes:
        def rounded(values: tuple[float, ...] | None, digits: int) -> list[float] | None:
            return None if values is None else [round(float(v), digits) for v in values]

        body: dict[str, Any] = {
            "ts": round(float(self.ts), 3),
            "state": str(self.state),
            "id": self.id,
            "bbox": rounded(self.bbox, 1),
            "bbox_norm": rounded(self.bbox_norm(), 4),
            "confidence": None if self.confidence is None else round(self.confidence, 3),
            "velocity": rounded(self.velocity, 1),
            "frame_size": list(self.frame_size),
            "tracker": self.tracker,
        }
        if self.transitions:
            body["transitions"] = list(self.transitions)
        return json.dumps(body, separators=(",", ":"), allow_nan=False).encode()


@dataclass(frozen=True)
class PtzState:
    """The last motion command sent to the dome: pan speed (-64..64, <0 left), tilt speed
    (-63..63, >0 up), zoom (-1 wide, 0 none, 1 tele), and who commanded it."""

    pan: int
    tilt: int
    zoom: int
    source: str = "auto"

    def to_payload(self) -> bytes:
        zoom = {-1: "out", 0: "none", 1: "in"}.get(self.zoom, str(self.zoom))
        body = {"pan": self.pan, "tilt": self.tilt, "zoom": zoom, "source": self.source}
        return json.dumps(body, separators=(",", ":")).encode()


def on_off(value: bool) -> bytes:
    return b"ON" if value else b"OFF"


# ---------------------------------------------------------------- incoming


class CommandError(PtzdError):
    """A rejected command payload: where it came from, why, and how big it was."""

    def __init__(self, topic: str, reason: str, payload: bytes) -> None:
        self.topic = topic
        self.reason = reason
        self.payload_size = len(payload)
        self.preview = _preview(payload)
        super().__init__(f"{topic}: {reason}")

    def to_payload(self, ts: float) -> bytes:
        body = {
            "ts": round(ts, 3),
            "topic": self.topic,
            "error": self.reason,
            "payload_bytes": self.payload_size,
            "payload_preview": self.preview,
        }
        return json.dumps(body, separators=(",", ":")).encode()


def _preview(payload: bytes, limit: int = 64) -> str:
    """A short, printable, log-safe view of a payload (never the whole of a large one)."""
    text = payload[:limit].decode("utf-8", errors="replace")
    text = "".join(ch if ch.isprintable() else "\N{REPLACEMENT CHARACTER}" for ch in text)
    return text + ("..." if len(payload) > limit else "")


class MoveDirection(StrEnum):
    LEFT = "left"
    RIGHT = "right"
    UP = "up"
    DOWN = "down"


class ZoomDirection(StrEnum):
    IN = "in"
    OUT = "out"


@dataclass(frozen=True)
class SetAutotrack:
    """`autotrack/set`: ON resumes tracking; OFF stops tracking and the dome."""

    enabled: bool


@dataclass(frozen=True)
class GotoPreset:
    """`preset_<n>`: autotracking pauses, the dome goes to preset n (1..255)."""

    number: int


@dataclass(frozen=True)
class Move:
    """`MOVE_<DIR>`: move continuously at the manual speed until `STOP` (Frigate semantics)."""

    direction: MoveDirection


@dataclass(frozen=True)
class ZoomMove:
    """`ZOOM_IN` / `ZOOM_OUT`: zoom continuously until `STOP`."""

    direction: ZoomDirection


@dataclass(frozen=True)
class Stop:
    """`STOP`: stop all motion now."""


@dataclass(frozen=True)
class SelectTarget:
    """`{"select": [x, y, w, h]}`: track the object in this box (view pixels); with
    `"ts"`, seconds since the Unix epoch of the frame it was drawn on (a `TrackMessage`'s
    `ts`), so the daemon can move the box with the camera since then."""

    bbox: BBox
    ts: float | None = None


PtzCommand = GotoPreset | Move | ZoomMove | Stop | SelectTarget
Command = SetAutotrack | PtzCommand

_PRESET = re.compile(r"preset_([0-9]{1,3})", re.IGNORECASE)
_WORDS: dict[str, PtzCommand] = {
    "MOVE_LEFT": Move(MoveDirection.LEFT),
    "MOVE_RIGHT": Move(MoveDirection.RIGHT),
    "MOVE_UP": Move(MoveDirection.UP),
    "MOVE_DOWN": Move(MoveDirection.DOWN),
    "ZOOM_IN": ZoomMove(ZoomDirection.IN),
    "ZOOM_OUT": ZoomMove(ZoomDirection.OUT),
    "STOP": Stop(),
}
MAX_SELECT_COORD = 100_000.0
MAX_TS = 1e11  # seconds since the epoch: year 5138; a bound that also keeps float() finite


def _text(topic: str, payload: bytes, max_bytes: int) -> str:
    if len(payload) > max_bytes:
        raise CommandError(
            topic, f"payload too large ({len(payload)} > {max_bytes} bytes)", payload
        )
    try:
        text = payload.decode("utf-8")
    except UnicodeDecodeError:
        raise CommandError(topic, "payload is not UTF-8 text", payload) from None
    if any(not ch.isprintable() and ch not in "\t\r\n" for ch in text):
        raise CommandError(topic, "payload has control characters", payload)
    text = text.strip()
    if not text:
        raise CommandError(topic, "empty payload", payload)
    return text


def parse_autotrack(topic: str, payload: bytes, *, max_bytes: int = 1024) -> SetAutotrack:
    """`ON` / `OFF` in any case (surrounding whitespace ignored)."""
    text = _text(topic, payload, max_bytes).upper()
    if text == "ON":
        return SetAutotrack(True)
    if text == "OFF":
        return SetAutotrack(False)
    raise CommandError(topic, "expected ON or OFF", payload)


def parse_ptz(topic: str, payload: bytes, *, max_bytes: int = 1024) -> PtzCommand:
    """Frigate's words (`preset_<n>`, `MOVE_LEFT|RIGHT|UP|DOWN`, `ZOOM_IN|OUT`, `STOP`, any
    case) or a JSON object `{"select": [x, y, w, h]}` with w, h > 0 and optionally
    `"ts": <seconds since the Unix epoch of the frame the box was drawn on>`."""
    text = _text(topic, payload, max_bytes)
    if text.startswith("{"):
        return _parse_select(topic, text, payload)
    word = _WORDS.get(text.upper())
    if word is not None:
        return word
    match = _PRESET.fullmatch(text)
    if match:
        number = int(match.group(1))
        if not 1 <= number <= 255:
            raise CommandError(topic, f"preset number {number} outside 1..255", payload)
        return GotoPreset(number)
    raise CommandError(
        topic,
        "unknown command (expected preset_<n>, MOVE_LEFT|RIGHT|UP|DOWN, ZOOM_IN|OUT, STOP "
        'or {"select": [x, y, w, h]})',
        payload,
    )


def _parse_select(topic: str, text: str, payload: bytes) -> SelectTarget:
    try:
        obj = json.loads(text)
    except json.JSONDecodeError as exc:
        raise CommandError(topic, f"malformed JSON: {exc.msg} at {exc.pos}", payload) from None
    if not isinstance(obj, dict) or "select" not in obj or not set(obj) <= {"select", "ts"}:
        raise CommandError(
            topic, 'JSON command must be {"select": [x, y, w, h]} with an optional "ts"', payload
        )
    box = obj["select"]
    if (
        not isinstance(box, list)
        or len(box) != 4
        or not all(isinstance(v, int | float) and not isinstance(v, bool) for v in box)
    ):
        raise CommandError(topic, "select needs four numbers [x, y, w, h]", payload)
    # abs() <= bound first: it rejects NaN and infinities, and huge ints before float() overflows
    if not all(abs(v) <= MAX_SELECT_COORD for v in box):
        raise CommandError(topic, "select coordinates must be finite view pixels", payload)
    x, y, w, h = (float(v) for v in box)
    if w <= 0 or h <= 0:
        raise CommandError(topic, "select width and height must be > 0", payload)
    ts = obj.get("ts")
    if ts is None:
        return SelectTarget((x, y, w, h))
    # (NaN and infinities fail the bounds; a huge int is compared exactly, not converted)
    if not isinstance(ts, int | float) or isinstance(ts, bool) or not 0 < ts <= MAX_TS:
        raise CommandError(topic, "ts must be seconds since the Unix epoch (> 0)", payload)
    return SelectTarget((x, y, w, h), float(ts))
