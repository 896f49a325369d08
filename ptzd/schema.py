"""The base of every configuration model: frozen, no unknown keys."""

from __future__ import annotations

from pydantic import BaseModel, ConfigDict


class StrictModel(BaseModel):
    """Frozen, `extra="forbid"` pydantic model; every config section derives from it."""

    model_config = ConfigDict(frozen=True, extra="forbid", validate_default=True)
