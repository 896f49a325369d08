"""The latest-value mailbox: drops never queue, counts drops, wakes consumers, closes."""

from __future__ import annotations

import asyncio

import pytest

from ptzd.mailbox import Mailbox, MailboxClosedError


def test_put_replaces_unread_item_and_counts_the_drop() -> None:
    box: Mailbox[int] = Mailbox("frames")
    for i in range(5):
        box.put(i)
    assert box.get_nowait() == 4
    assert box.get_nowait() is None
    assert (box.put_count, box.taken, box.dropped) == (5, 1, 4)


def test_taken_items_are_not_counted_as_dropped() -> None:
    box: Mailbox[str] = Mailbox("tracks")
    box.put("a")
    assert box.get_nowait() == "a"
    box.put("b")
    assert box.get_nowait() == "b"
    assert box.dropped == 0


async def test_get_waits_for_the_next_item() -> None:
    box: Mailbox[int] = Mailbox("frames")
    getter = asyncio.create_task(box.get())
    await asyncio.sleep(0)
    assert not getter.done()
    box.put(7)
    assert await asyncio.wait_for(getter, 1.0) == 7


async def test_slow_consumer_sees_only_the_latest() -> None:
    box: Mailbox[int] = Mailbox("frames")
    seen: list[int] = []

    async def consumer() -> None:
        while True:
            try:
                seen.append(await box.get())
            except MailboxClosedError:
                return
            await asyncio.sleep(0.01)  # slower than the producer

    task = asyncio.create_task(consumer())
    for i in range(50):
        box.put(i)
        await asyncio.sleep(0.001)
    box.close()
    await asyncio.wait_for(task, 2.0)
    assert seen == sorted(seen)  # in order, never stale
    assert seen[-1] == 49  # the last item is delivered even after close
    assert box.dropped == 50 - len(seen)
    assert box.dropped > 0


async def test_close_wakes_a_waiting_consumer() -> None:
    box: Mailbox[int] = Mailbox("frames")
    getter = asyncio.create_task(box.get())
    await asyncio.sleep(0)
    box.close()
    with pytest.raises(MailboxClosedError):
        await asyncio.wait_for(getter, 1.0)
    with pytest.raises(MailboxClosedError):
        box.put(1)
