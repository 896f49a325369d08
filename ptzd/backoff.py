"""Reconnect backoff shared by every link that retries (serial port, MQTT broker)."""

from __future__ import annotations

import random


def backoff_delay(attempt: int, low: float, high: float, rng: random.Random) -> float:
    """Delay before reconnect attempt `attempt` (0-based): exponential from `low`, capped at
    `high`, with "equal jitter" (half fixed, half uniform) so a fleet of daemons restarted
    together does not hammer the broker or bus in lockstep. The exponent is capped so a port
    that stays away for days never overflows."""
    cap = min(high, low * 2.0 ** min(attempt, 30))
    return cap / 2.0 + rng.uniform(0.0, cap / 2.0)
