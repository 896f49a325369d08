"""Injectable time: the daemon and simulator never read the wall clock directly.

`RealClock` is monotonic time. `VirtualClock` is advanced by hand or by `run_until`: it
makes runs fast and repeatable; everything that needs time takes a `Clock`.
"""

from __future__ import annotations

import asyncio
import heapq
import time
from typing import Protocol


class Clock(Protocol):
    """Seconds on a monotonic time line, and a way to wait on it."""

    def now(self) -> float: ...

    async def sleep(self, seconds: float) -> None: ...


class RealClock:
    """Monotonic wall time (`time.monotonic`) and `asyncio.sleep`."""

    def now(self) -> float:
        return time.monotonic()

    async def sleep(self, seconds: float) -> None:
        await asyncio.sleep(max(0.0, seconds))


_FALLBACK_YIELDS = 64


class VirtualClock:
    """Manually advanced time: sleeps resolve only when the time is advanced past them.

    Deterministic: sleepers wake in (deadline, order of sleeping) order, and `now()` reads the
    deadline being served while they run. Drive it either by hand (`advance`, `advance_to`)
    or with `run_until`, which jumps straight from one deadline to the next whenever every
    task on the event loop is waiting, so a simulated minute takes as long as its work.
    """

    def __init__(self, start: float = 0.0) -> None:
        self._now = float(start)
        self._sleepers: list[tuple[float, int, asyncio.Future[None]]] = []
        self._order = 0

    def now(self) -> float:
        return self._now

    async def sleep(self, seconds: float) -> None:
        if seconds <= 0.0:
            await asyncio.sleep(0)
            return
        future: asyncio.Future[None] = asyncio.get_running_loop().create_future()
        heapq.heappush(self._sleepers, (self._now + seconds, self._order, future))
        self._order += 1
        await future

    def next_deadline(self) -> float | None:
        """The earliest pending wake-up time, ignoring sleeps that were cancelled."""
        while self._sleepers and self._sleepers[0][2].done():
            heapq.heappop(self._sleepers)
        return self._sleepers[0][0] if self._sleepers else None

    def advance_to(self, when: float) -> None:
        """Set the time to `when` (never backwards) and wake every sleeper due by then.

        Woken tasks run when the caller next yields to the event loop; use `run_until` to
        let each wake-up run at its own time.
        """
        if when < self._now:
            raise ValueError(f"virtual time cannot go back from {self._now} to {when}")
        while self._sleepers and self._sleepers[0][0] <= when:
            _, _, future = heapq.heappop(self._sleepers)
            if not future.done():
                future.set_result(None)
        self._now = when

    def advance(self, seconds: float) -> None:
        """`advance_to(now + seconds)`."""
        self.advance_to(self._now + seconds)

    async def settle(self) -> None:
        """Yield until no task on the event loop is ready to run (all wait on something)."""
        loop = asyncio.get_running_loop()
        ready = getattr(loop, "_ready", None)  # CPython's run queue; absent on other loops
        if ready is None:
            # without the run queue a fixed number of yields is still deterministic
            for _ in range(_FALLBACK_YIELDS):
                await asyncio.sleep(0)
            return
        while True:
            await asyncio.sleep(0)
            if not ready:
                return

    async def run_until(self, when: float) -> None:
        """Advance through every deadline up to `when`, letting each wake-up run at its time."""
        await self.settle()
        while True:
            deadline = self.next_deadline()
            if deadline is None or deadline > when:
                break
            self.advance_to(max(deadline, self._now))
            await self.settle()
        self.advance_to(max(when, self._now))
        await self.settle()
