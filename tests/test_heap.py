"""`ptzd.heap`: glibc malloc's account of the heap, and `trim` handing free pages back."""

from __future__ import annotations

import json
import subprocess
import sys

import pytest

from ptzd import heap

GLIBC = bool(heap.malloc_stats())

# Frees 200 blocks of 0.1-0.6 MB, each with a small live block allocated after it, on a
# second thread (its own malloc arena, as the daemon's vision worker has): the freed space
# sits between live blocks, so malloc cannot give it back by shrinking the heap's top.
FRAGMENT_THEN_TRIM = """
import json, os, threading
import numpy as np
from ptzd import heap
from ptzd.soak import proc_sample

def anon_mb():
    return proc_sample(os.getpid())["rss_anon_mb"]

pins = []
def fragment():
    # freeing a 1 MB mmapped block raises malloc's mmap threshold to 1 MB (glibc adapts
    # it), so the blocks below come from the arena, as the daemon's frame-sized ones do
    first = np.ones(1_000_000, np.uint8)
    del first
    sizes = np.random.default_rng(0).integers(100_000, 600_000, 200)
    blocks = []
    for size in sizes:
        blocks.append(np.ones(int(size), np.uint8))
        pins.append(np.ones(64, np.uint8))
    blocks.clear()

thread = threading.Thread(target=fragment)
thread.start()
thread.join()
before, stats = anon_mb(), heap.malloc_stats()
released = heap.trim()
print(json.dumps({"before": before, "after": anon_mb(), "released": released, **stats}))
"""


@pytest.mark.skipif(not GLIBC, reason="glibc only (mallinfo2, malloc_trim)")
def test_trim_gives_the_free_pages_between_live_blocks_back() -> None:
    run = subprocess.run([sys.executable, "-c", FRAGMENT_THEN_TRIM], capture_output=True,
                         text=True, check=True, timeout=60)  # fmt: skip
    out = json.loads(run.stdout)
    assert out["malloc_free_mb"] > 30  # ~70 MB freed, kept by malloc...
    assert out["before"] - out["after"] > 30  # ...until trimmed
    assert out["released"] is True


# 64 MB: above glibc's largest mmap threshold (32 MB on 64-bit), so mmapped - unless the
# arena already holds a free chunk that big: malloc looks there first. In the pytest process
# earlier tests once left one (in use +64, mmapped +0), so this runs in a fresh interpreter.
LIVE_ARRAY = """
import json
import numpy as np
from ptzd import heap

before = heap.malloc_stats()
block = np.ones(64 * 1024 * 1024, np.uint8)
during = heap.malloc_stats()
del block
after = heap.malloc_stats()
print(json.dumps({"before": before, "during": during, "after": after}))
"""


@pytest.mark.skipif(not GLIBC, reason="glibc only (mallinfo2, malloc_trim)")
def test_malloc_stats_count_a_live_array_as_in_use() -> None:
    run = subprocess.run([sys.executable, "-c", LIVE_ARRAY], capture_output=True, text=True,
                         check=True, timeout=60)  # fmt: skip
    out = json.loads(run.stdout)
    before, during, after = out["before"], out["during"], out["after"]
    assert during["malloc_in_use_mb"] - before["malloc_in_use_mb"] == pytest.approx(64, abs=1)
    assert during["malloc_mmapped_mb"] - before["malloc_mmapped_mb"] == pytest.approx(64, abs=1)
    assert after["malloc_in_use_mb"] < during["malloc_in_use_mb"] - 60
