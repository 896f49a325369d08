"""The daemon's configuration: one frozen pydantic model loaded from TOML.

Each stage owns its section model (`ptzd/<stage>/config.py`); this module composes
them, applies `PTZD_<SECTION>__<KEY>` environment overrides and turns validation
failures into a `ConfigError` that names every offending key.
"""

from __future__ import annotations

import json
import os
import tomllib
from collections.abc import Mapping
from pathlib import Path
from typing import Any, Literal, Self

from pydantic import Field, ValidationError, model_validator

from ptzd.control.config import ControlConfig
from ptzd.errors import ConfigError
from ptzd.mqtt.config import MqttConfig
from ptzd.pelco.config import SerialConfig
from ptzd.schema import StrictModel
from ptzd.sim.config import SimConfig
from ptzd.vision.acquisition_config import AcquisitionConfig
from ptzd.vision.config import TrackerConfig
from ptzd.vision.detect.config import DetectorConfig

ENV_PREFIX = "PTZD_"
ENV_SEPARATOR = "__"


class CameraConfig(StrictModel):
    """Identity of the camera this daemon drives."""

    name: str = Field(default="cam1", pattern=r"^[A-Za-z0-9_\-]{1,64}$")


class LoggingConfig(StrictModel):
    """Log level and format; `auto` means console on a TTY, JSON otherwise."""

    level: Literal["debug", "info", "warning", "error"] = "info"
    format: Literal["auto", "json", "console"] = "auto"


class CaptureConfig(StrictModel):
    """Where frames come from: a file, RTSP/HTTP URL, V4L2 device, or `sim`."""

    source: str = Field(default="sim", min_length=1)
    # how old a frame is when cv2 hands it over (exposure, encoding, network, the decoder's
    # buffer): the dome's pose for a frame is its pose this long before it arrived
    latency_s: float = Field(default=0.0, ge=0.0, le=2.0)
    # the frames of the last this many seconds are kept: a select whose `ts` names one of
    # them starts the tracker there and follows the target to the newest (docs/mqtt.md);
    # 0: a late box is only moved by the dome's motion
    select_history_s: float = Field(default=0.5, ge=0.0, le=5.0)


class Config(StrictModel):
    """The whole configuration, one section per stage."""

    camera: CameraConfig = CameraConfig()
    logging: LoggingConfig = LoggingConfig()
    capture: CaptureConfig = CaptureConfig()
    serial: SerialConfig = SerialConfig()
    tracker: TrackerConfig = TrackerConfig()
    detector: DetectorConfig = DetectorConfig()
    acquisition: AcquisitionConfig = AcquisitionConfig()
    control: ControlConfig = ControlConfig()
    mqtt: MqttConfig = MqttConfig()
    sim: SimConfig = SimConfig()

    @model_validator(mode="after")
    def _frames_younger_than_stale(self) -> Self:
        if self.capture.latency_s >= self.control.max_track_age_s:
            raise ValueError(
                f"capture.latency_s ({self.capture.latency_s}) must be below "
                f"control.max_track_age_s ({self.control.max_track_age_s}): every frame "
                "would arrive stale"
            )
        return self


def _parse_env_value(raw: str) -> object:
    """Read an override as a TOML value (`20`, `true`, `[1, 2]`), else as a plain string."""
    try:
        return tomllib.loads(f"v = {raw}")["v"]
    except tomllib.TOMLDecodeError:
        return raw


def env_overrides(environ: Mapping[str, str]) -> dict[str, Any]:
    """Nested dict of the `PTZD_SECTION__KEY=value` variables in `environ`.

    Only variables with the separator count, so unrelated `PTZD_*` variables are ignored.
    """
    tree: dict[str, Any] = {}
    for name, raw in sorted(environ.items()):
        if not name.startswith(ENV_PREFIX) or ENV_SEPARATOR not in name:
            continue
        path = name[len(ENV_PREFIX) :].lower().split(ENV_SEPARATOR)
        if any(not part for part in path):
            continue
        node = tree
        for part in path[:-1]:
            child = node.setdefault(part, {})
            if not isinstance(child, dict):
                break
            node = child
        else:
            node[path[-1]] = _parse_env_value(raw)
    return tree


def merge_tables(base: dict[str, Any], override: Mapping[str, Any]) -> dict[str, Any]:
    """`base` with `override` laid over it, table by table (neither is changed)."""
    merged = dict(base)
    for key, value in override.items():
        if isinstance(value, Mapping) and isinstance(merged.get(key), dict):
            merged[key] = merge_tables(merged[key], value)
        else:
            merged[key] = value
    return merged


MASK = "**********"


def _redact(key: str, value: object) -> object:
    """Never echo a secret in an error: `*password*` keys, also inside a table's input."""
    if "password" in key.rsplit(".", 1)[-1]:
        return MASK
    if isinstance(value, Mapping):
        return {k: _redact(str(k), v) for k, v in value.items()}
    return value


def _problems(exc: ValidationError) -> list[tuple[str, str, object]]:
    out: list[tuple[str, str, object]] = []
    for err in exc.errors(include_url=False):
        key = ".".join(str(part) for part in err["loc"]) or "<root>"
        out.append((key, err["msg"], _redact(key, err.get("input"))))
    return out


def validate_config(
    data: Mapping[str, Any], *, source: str = "<config>", environ: Mapping[str, str] | None = None
) -> Config:
    """Validate a parsed TOML document with environment overrides applied on top."""
    merged = merge_tables(dict(data), env_overrides(os.environ if environ is None else environ))
    try:
        return Config.model_validate(merged)
    except ValidationError as exc:
        raise ConfigError(source, _problems(exc)) from None


def load_config(path: str | Path, *, environ: Mapping[str, str] | None = None) -> Config:
    """Load, override and validate a TOML config file; raise `ConfigError` on any problem."""
    source = str(path)
    try:
        text = Path(path).read_text(encoding="utf-8")
    except OSError as exc:
        raise ConfigError(source, [("<file>", exc.strerror or str(exc), source)]) from None
    except UnicodeDecodeError as exc:
        raise ConfigError(source, [("<file>", f"not UTF-8 text: {exc.reason}", source)]) from None
    try:
        data = tomllib.loads(text)
    except tomllib.TOMLDecodeError as exc:
        raise ConfigError(source, [("<toml>", str(exc), None)]) from None
    return validate_config(data, source=source, environ=environ)


def _toml_value(value: object) -> str:
    if isinstance(value, bool):
        return "true" if value else "false"
    if isinstance(value, int | float):
        return repr(value)
    if isinstance(value, list | tuple):
        return "[" + ", ".join(_toml_value(v) for v in value) + "]"
    # JSON string escaping is a subset of TOML basic-string escaping.
    return json.dumps(str(value))


def to_toml(config: Config) -> str:
    """Render the effective config as TOML; secrets come out masked by their own types."""
    lines: list[str] = []

    def emit(table: Mapping[str, Any], prefix: str) -> None:
        scalars = {k: v for k, v in table.items() if not isinstance(v, Mapping) and v is not None}
        tables = {k: v for k, v in table.items() if isinstance(v, Mapping)}
        if prefix and scalars:
            lines.append(f"[{prefix}]")
        for key, value in scalars.items():
            lines.append(f"{key} = {_toml_value(value)}")
        if prefix and scalars:
            lines.append("")
        for key, value in tables.items():
            emit(value, f"{prefix}.{key}" if prefix else key)

    emit(config.model_dump(mode="json"), "")
    return "\n".join(lines).rstrip() + "\n"
