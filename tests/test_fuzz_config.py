"""Every bounded config field, set just out of range, gives a ConfigError naming its key.

The cases are generated from the model's own field bounds (`ge`/`gt`/`le`/`lt`/lengths), so
a new bounded field is covered without touching this file.
"""

from __future__ import annotations

import math
import subprocess
import sys
from pathlib import Path
from typing import Any

import annotated_types as at
import pytest
from pydantic import BaseModel

from ptzd.config import Config, validate_config
from ptzd.errors import ConfigError


def _nested(model: Any) -> type[BaseModel] | None:
    return model if isinstance(model, type) and issubclass(model, BaseModel) else None


def _is_int(annotation: object) -> bool:
    return annotation is int


def out_of_range_cases(model: type[BaseModel], prefix: str = "") -> list[tuple[str, object]]:
    """(dotted key, bad value) for every bound of every field, recursively."""
    cases: list[tuple[str, object]] = []
    for name, field in model.model_fields.items():
        key = f"{prefix}{name}"
        sub = _nested(field.annotation)
        if sub is not None:
            cases += out_of_range_cases(sub, f"{key}.")
            continue
        step: float = 1 if _is_int(field.annotation) else 1e-6
        for bound in field.metadata:
            if isinstance(bound, at.Ge):
                cases.append((key, _below(bound.ge, step)))
            elif isinstance(bound, at.Gt):
                cases.append((key, bound.gt))
            elif isinstance(bound, at.Le):
                cases.append((key, _above(bound.le, step)))
            elif isinstance(bound, at.Lt):
                cases.append((key, bound.lt))
            elif isinstance(bound, at.MinLen) and bound.min_length > 0:
                cases.append((key, ""))
            elif isinstance(bound, at.MaxLen):
                cases.append((key, "x" * (bound.max_length + 1)))
    return cases


def _below(value: Any, step: float) -> object:
    return (
        value - step if step == 1 else math.nextafter(float(value), -math.inf) - abs(value) * 1e-9
    )


def _above(value: Any, step: float) -> object:
    return value + step if step == 1 else math.nextafter(float(value), math.inf) + abs(value) * 1e-9


def _as_tree(key: str, value: object) -> dict[str, Any]:
    tree: dict[str, Any] = {}
    node = tree
    parts = key.split(".")
    for part in parts[:-1]:
        node = node.setdefault(part, {})
    node[parts[-1]] = value
    return tree


CASES = out_of_range_cases(Config)


def test_the_model_has_many_bounded_fields() -> None:
    # guards the generator itself: if pydantic stopped exposing bounds this would be empty
    assert len(CASES) > 50
    assert {k.split(".")[0] for k, _ in CASES} >= {"serial", "tracker", "control", "mqtt"}


@pytest.mark.parametrize(("key", "value"), CASES, ids=[f"{k}={v!r}"[:60] for k, v in CASES])
def test_out_of_range_value_names_its_key(key: str, value: object) -> None:
    with pytest.raises(ConfigError) as info:
        validate_config(_as_tree(key, value), environ={})
    keys = [problem[0] for problem in info.value.problems]
    assert key in keys, f"{key}={value!r} reported as {info.value}"


@pytest.mark.parametrize(
    ("text", "key"),
    [
        ("[serial]\nbaud = true\n", "serial"),
        ("[control]\nnope = 1\n", "control.nope"),
        ("[mqtt]\nkeepalive_s = 'x'\n", "mqtt.keepalive_s"),
        ("serial = 3\n", "serial"),
        ("[camera]\nname = 'a b'\n", "camera.name"),
        ("[serial\n", "<toml>"),
    ],
)
def test_malformed_files_name_the_key(tmp_path: Path, text: str, key: str) -> None:
    path = tmp_path / "bad.toml"
    path.write_text(text)
    run = subprocess.run(
        [sys.executable, "-m", "ptzd", "check-config", str(path)],
        capture_output=True,
        text=True,
        timeout=60,
    )
    assert run.returncode == 2
    assert f": {key}" in run.stderr
    assert "Traceback" not in run.stderr


def test_binary_file_is_a_clear_error(tmp_path: Path) -> None:
    path = tmp_path / "bin.toml"
    path.write_bytes(bytes(range(256)))
    with pytest.raises(ConfigError) as info:
        from ptzd.config import load_config

        load_config(path, environ={})
    assert info.value.problems[0][0] == "<file>"
