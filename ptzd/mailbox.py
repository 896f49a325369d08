"""A single-slot, latest-value mailbox between pipeline stages.

A producer never waits and nothing is queued: `put` replaces an item the consumer has not
taken yet, and that replaced item is counted in `dropped`. A consumer `await`s `get()` for
the next item it has not seen. This is how a slow stage (vision) always works on the newest
frame instead of falling further behind. Use from one event loop (not thread-safe).
"""

from __future__ import annotations

import asyncio
from typing import Generic, TypeVar, cast

T = TypeVar("T")


class MailboxClosedError(Exception):
    """`get` on a closed, empty mailbox (or `put` on a closed one)."""


class Mailbox(Generic[T]):
    """Holds at most one item: the latest one put and not yet taken."""

    def __init__(self, name: str) -> None:
        self.name = name
        self._item: T | None = None
        self._full = False
        self._closed = False
        self._changed = asyncio.Event()
        self.put_count = 0
        self.taken = 0
        self.dropped = 0

    @property
    def closed(self) -> bool:
        return self._closed

    def put(self, item: T) -> None:
        """Store `item`, dropping (and counting) any item not yet taken."""
        if self._closed:
            raise MailboxClosedError(self.name)
        if self._full:
            self.dropped += 1
        self._item = item
        self._full = True
        self.put_count += 1
        self._changed.set()

    def get_nowait(self) -> T | None:
        """The waiting item, or None if there is none."""
        return self._take() if self._full else None

    def _take(self) -> T:
        item = cast(T, self._item)
        self._item, self._full = None, False
        self.taken += 1
        self._changed.clear()
        return item

    async def get(self) -> T:
        """Wait for an item and take it; raises `MailboxClosedError` once closed and empty."""
        await self.ready()
        if not self._full:
            raise MailboxClosedError(self.name)
        return self._take()

    async def ready(self) -> None:
        """Return once an item is waiting or the mailbox is closed (takes nothing)."""
        while not self._full and not self._closed:
            self._changed.clear()
            await self._changed.wait()

    def close(self) -> None:
        """No more puts; waiting consumers wake (and get any last item first)."""
        self._closed = True
        self._changed.set()
