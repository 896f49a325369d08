"""Configuration of the Pelco serial link (`[serial]`)."""

from __future__ import annotations

from typing import Literal, Self

from pydantic import Field, model_validator

from ptzd.schema import StrictModel

DEFAULT_BAUDRATE = {"p": 4800, "d": 2400}


class SerialConfig(StrictModel):
    """How ptzd reaches the dome: port, protocol, address, wire settings and link timing."""

    port: str = Field(default="/dev/ttyUSB0", min_length=1, description="pyserial URL or device")
    protocol: Literal["p", "d"] = "p"
    address: int = Field(default=1, ge=1, le=255)
    baudrate: int | None = Field(default=None, ge=300, le=115200)
    bytesize: Literal[7, 8] = 8
    parity: Literal["none", "even", "odd"] = "none"
    stopbits: Literal[1, 2] = 1
    # seconds between the end of one frame on the wire and the start of the next
    min_gap_s: float = Field(default=0.05, ge=0.0, le=2.0)
    # repeat the motion in force this often while the dome moves
    keepalive_s: float = Field(default=2.0, gt=0.0, le=60.0)
    # STOP when no fresh motion command arrived for this long
    deadman_s: float = Field(default=3.0, gt=0.0, le=300.0)
    reconnect_min_s: float = Field(default=0.5, gt=0.0, le=60.0)
    reconnect_max_s: float = Field(default=10.0, gt=0.0, le=600.0)

    @property
    def effective_baudrate(self) -> int:
        """`baudrate`, or the protocol's customary rate (Pelco-P 4800, Pelco-D 2400)."""
        return self.baudrate if self.baudrate is not None else DEFAULT_BAUDRATE[self.protocol]

    @property
    def bits_per_byte(self) -> int:
        """Start bit + data bits + parity bit + stop bits: the wire cost of one byte."""
        return 1 + self.bytesize + (0 if self.parity == "none" else 1) + self.stopbits

    @model_validator(mode="after")
    def _timing_is_consistent(self) -> Self:
        if self.reconnect_min_s > self.reconnect_max_s:
            raise ValueError(
                f"reconnect_min_s ({self.reconnect_min_s}) must not exceed "
                f"reconnect_max_s ({self.reconnect_max_s})"
            )
        if self.min_gap_s >= self.keepalive_s:
            raise ValueError(
                f"min_gap_s ({self.min_gap_s}) must be shorter than "
                f"keepalive_s ({self.keepalive_s})"
            )
        if self.min_gap_s >= self.deadman_s:
            raise ValueError(
                f"min_gap_s ({self.min_gap_s}) must be shorter than deadman_s ({self.deadman_s})"
            )
        return self
