"""systemd's sd_notify protocol over a plain unix datagram socket (no libsystemd).

`Notifier.from_environ()` reads `$NOTIFY_SOCKET` (a path, or `@name` for the abstract
namespace); outside systemd it is a no-op. `Watchdog` sends `WATCHDOG=1` every
`WATCHDOG_USEC / 2` but only while the daemon's health predicate holds (fresh frames and
control ticks), so a wedged pipeline gets restarted by systemd instead of being kept
alive by a timer that only proves the event loop still turns.

Daemon wiring::

    notifier = Notifier.from_environ()
    beats = Heartbeats(("frame", "control"))       # beat() per frame / per control tick
    dog = Watchdog.from_environ(notifier, lambda: beats.fresh(2.0))
    if dog is not None:
        group.create_task(dog.run(), name="watchdog")
    notifier.ready(status="tracking")                # serial open and first frame arrived
    ...
    notifier.stopping()                              # on shutdown, before STOP to the dome
"""

from __future__ import annotations

import os
import socket
from collections.abc import Callable, Mapping

from ptzd.clock import Clock, RealClock
from ptzd.logs import get_logger

log = get_logger("sdnotify")


def _socket_address(raw: str) -> str | None:
    if raw.startswith("@"):
        return "\0" + raw[1:]  # abstract namespace
    if raw.startswith("/"):
        return raw
    return None  # e.g. vsock: addresses, not used on a surveillance box


class Notifier:
    """Sends `KEY=value` lines to systemd. Never raises: a lost notification is logged."""

    def __init__(self, address: str | None) -> None:
        self.address = address
        self.sent = 0
        self.failed = 0
        self._sock: socket.socket | None = None

    @classmethod
    def from_environ(cls, environ: Mapping[str, str] | None = None) -> Notifier:
        env = os.environ if environ is None else environ
        raw = env.get("NOTIFY_SOCKET", "")
        return cls(_socket_address(raw) if raw else None)

    @property
    def enabled(self) -> bool:
        return self.address is not None

    def notify(self, **fields: str | int) -> bool:
        """Send one datagram of `KEY=value` lines (keys upper-cased); True if sent."""
        if self.address is None:
            return False
        body = "\n".join(f"{key.upper()}={value}" for key, value in fields.items())
        try:
            if self._sock is None:
                self._sock = socket.socket(socket.AF_UNIX, socket.SOCK_DGRAM | socket.SOCK_CLOEXEC)
                self._sock.setblocking(False)  # never stall the event loop on a full queue
            self._sock.sendto(body.encode(), self.address)
        except OSError as exc:
            self.failed += 1
            log.warning("sd_notify_failed", error=str(exc), fields=sorted(fields))
            return False
        self.sent += 1
        return True

    def ready(self, status: str | None = None) -> bool:
        if status is None:
            return self.notify(ready=1)
        return self.notify(ready=1, status=status)

    def status(self, text: str) -> bool:
        return self.notify(status=text.replace("\n", " "))

    def watchdog(self) -> bool:
        return self.notify(watchdog=1)

    def stopping(self, status: str | None = None) -> bool:
        if status is None:
            return self.notify(stopping=1)
        return self.notify(stopping=1, status=status)

    def close(self) -> None:
        if self._sock is not None:
            self._sock.close()
            self._sock = None


def watchdog_interval(environ: Mapping[str, str] | None = None) -> float | None:
    """Seconds between pings (half of `WATCHDOG_USEC`), or None when no watchdog is armed
    for this process (`WATCHDOG_PID`, when set, must be our pid)."""
    env = os.environ if environ is None else environ
    usec = env.get("WATCHDOG_USEC", "")
    pid = env.get("WATCHDOG_PID", "")
    if pid and pid != str(os.getpid()):
        return None
    try:
        value = int(usec)
    except ValueError:
        return None
    return value / 2e6 if value > 0 else None


class Heartbeats:
    """Last time each pipeline stage reported progress; healthy when all are recent.

    The daemon calls `beat("frame")` per captured frame and `beat("control")` per control
    tick; `fresh(max_age_s)` is the watchdog's health predicate.
    """

    def __init__(self, stages: tuple[str, ...], *, clock: Clock | None = None) -> None:
        self._clock: Clock = clock if clock is not None else RealClock()
        self._last: dict[str, float | None] = dict.fromkeys(stages)

    def beat(self, stage: str) -> None:
        if stage not in self._last:
            raise KeyError(f"unknown stage {stage!r}; known: {sorted(self._last)}")
        self._last[stage] = self._clock.now()

    def stale(self, max_age_s: float) -> list[str]:
        now = self._clock.now()
        return [s for s, t in self._last.items() if t is None or now - t > max_age_s]

    def fresh(self, max_age_s: float) -> bool:
        return not self.stale(max_age_s)


class Watchdog:
    """Pings `WATCHDOG=1` every `interval_s` while `healthy()` is true. Run as a task."""

    def __init__(
        self,
        notifier: Notifier,
        interval_s: float,
        healthy: Callable[[], bool],
        *,
        clock: Clock | None = None,
    ) -> None:
        if interval_s <= 0:
            raise ValueError(f"watchdog interval must be > 0, got {interval_s}")
        self.notifier = notifier
        self.interval_s = interval_s
        self.healthy = healthy
        self.pings = 0
        self.skipped = 0
        self._clock: Clock = clock if clock is not None else RealClock()

    @classmethod
    def from_environ(
        cls,
        notifier: Notifier,
        healthy: Callable[[], bool],
        *,
        environ: Mapping[str, str] | None = None,
        clock: Clock | None = None,
    ) -> Watchdog | None:
        """A watchdog pinging at `WATCHDOG_USEC / 2`, or None when systemd armed none."""
        interval = watchdog_interval(environ)
        if interval is None or not notifier.enabled:
            return None
        return cls(notifier, interval, healthy, clock=clock)

    async def run(self) -> None:
        was_healthy = True
        while True:
            ok = self.healthy()
            if ok:
                self.notifier.watchdog()
                self.pings += 1
                if not was_healthy:
                    log.info("watchdog_resumed")
            else:
                self.skipped += 1
                if was_healthy:
                    log.warning("watchdog_withheld", reason="pipeline unhealthy")
            was_healthy = ok
            # after a withheld ping look again sooner: a pipeline that recovers from a short
            # hiccup must ping well before systemd's full WatchdogSec (2 intervals) runs out
            await self._clock.sleep(self.interval_s if ok else self.interval_s / 4)
