"""PelcoLink: command-to-wire latency and maximum command rate vs the physical limit.

For each baud rate (2400/4800/9600, Pelco-P 8-byte frames, 8N1) a real `PelcoLink` drives a
raw pty; the far end timestamps every frame as it arrives.

- latency: `link.send(motion)` on an idle line -> the frame's last byte read at the far end
  (median and p95 over `--samples` commands, each after the line went idle).
- rate: commands offered far faster than the wire (every 1 ms); frames that reached the wire
  per second, against the physical limit baud / (8 x 10) and the paced limit
  1 / (frame time + min_gap_s), measured with the default 50 ms gap and with no gap.

A pty does not emulate the baud rate, so the wire time is added by the link's own pacing, not
by the pty: these numbers show the link's overhead and pacing, not a UART's. The machine has 2
shared cores; numbers are noisy. Writes JSON to bench/results/pelco_link.json.

Run: .venv/bin/python bench/pelco_link.py [--samples 30] [--seconds 2]
"""

from __future__ import annotations

import argparse
import asyncio
import contextlib
import json
import os
import statistics
import time
import tty
from pathlib import Path

from ptzd.pelco.codec import FrameParser, Motion
from ptzd.pelco.config import SerialConfig
from ptzd.pelco.link import PelcoLink, frame_time

RESULTS = Path(__file__).resolve().parent / "results" / "pelco_link.json"
BAUDS = (2400, 4800, 9600)
FRAME_BYTES = 8


class Peer:
    def __init__(self) -> None:
        self.master, self.slave = os.openpty()
        tty.setraw(self.slave)
        os.set_blocking(self.master, False)
        self.parser = FrameParser()
        self.arrivals: list[float] = []
        self.arrived = asyncio.Event()
        asyncio.get_running_loop().add_reader(self.master, self._readable)

    def _readable(self) -> None:
        with contextlib.suppress(BlockingIOError):
            data = os.read(self.master, 4096)
            now = time.perf_counter()
            frames = self.parser.feed(data)
            self.arrivals += [now] * len(frames)
            if frames:
                self.arrived.set()

    def close(self) -> None:
        asyncio.get_running_loop().remove_reader(self.master)
        os.close(self.master)
        os.close(self.slave)


async def latency(baud: int, samples: int) -> list[float]:
    peer = Peer()
    config = SerialConfig(port=os.ttyname(peer.slave), baudrate=baud, deadman_s=60.0)
    out: list[float] = []
    try:
        async with PelcoLink(config) as link:
            await asyncio.sleep(0.3)
            for i in range(samples):
                await asyncio.sleep(frame_time(FRAME_BYTES, config) + config.min_gap_s + 0.01)
                peer.arrived.clear()
                count = len(peer.arrivals)
                sent = time.perf_counter()
                link.send(Motion(pan=1 + i % 2))
                await asyncio.wait_for(peer.arrived.wait(), 2.0)
                out.append(peer.arrivals[count] - sent)
    finally:
        peer.close()
    return out


async def rate(baud: int, seconds: float, gap: float) -> dict[str, float]:
    peer = Peer()
    config = SerialConfig(port=os.ttyname(peer.slave), baudrate=baud, min_gap_s=gap, deadman_s=60.0)
    try:
        async with PelcoLink(config) as link:
            await asyncio.sleep(0.3)
            start = time.perf_counter()
            i = 0
            while time.perf_counter() - start < seconds:
                link.send(Motion(pan=1 + i % 60))
                i += 1
                await asyncio.sleep(0.001)
            elapsed = time.perf_counter() - start
            await asyncio.sleep(0.1)
            # frames that arrived within the measured window only
            frames = sum(start <= t <= start + elapsed for t in peer.arrivals)
            coalesced = link.counters.coalesced
    finally:
        peer.close()
    wire = frame_time(FRAME_BYTES, config)
    return {
        "offered_per_s": i / elapsed,
        "frames_per_s": frames / elapsed,
        "physical_limit_per_s": 1.0 / wire,
        "paced_limit_per_s": 1.0 / (wire + gap),
        "coalesced": float(coalesced),
    }


async def main(samples: int, seconds: float) -> dict[str, object]:
    rows: list[dict[str, object]] = []
    for baud in BAUDS:
        lat = await latency(baud, samples)
        gap_default = await rate(baud, seconds, 0.05)
        no_gap = await rate(baud, seconds, 0.0)
        wire = FRAME_BYTES * 10 / baud
        rows.append(
            {
                "baud": baud,
                "frame_wire_ms": wire * 1000,
                "latency_median_ms": statistics.median(lat) * 1000,
                "latency_p95_ms": sorted(lat)[int(0.95 * (len(lat) - 1))] * 1000,
                "rate_gap50ms": gap_default,
                "rate_no_gap": no_gap,
            }
        )
    return {"samples": samples, "seconds": seconds, "frame_bytes": FRAME_BYTES, "rows": rows}


def print_table(result: dict[str, object]) -> None:
    print(
        f"{'baud':>5} {'wire ms':>8} {'lat med ms':>10} {'lat p95 ms':>10} "
        f"{'fps gap50':>9} {'paced lim':>9} {'fps no-gap':>10} {'phys lim':>8}"
    )
    rows = result["rows"]
    assert isinstance(rows, list)
    for row in rows:
        g, n = row["rate_gap50ms"], row["rate_no_gap"]
        print(
            f"{row['baud']:>5} {row['frame_wire_ms']:>8.2f} {row['latency_median_ms']:>10.2f} "
            f"{row['latency_p95_ms']:>10.2f} {g['frames_per_s']:>9.1f} "
            f"{g['paced_limit_per_s']:>9.1f} {n['frames_per_s']:>10.1f} "
            f"{n['physical_limit_per_s']:>8.1f}"
        )


if __name__ == "__main__":
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--samples", type=int, default=30)
    parser.add_argument("--seconds", type=float, default=2.0)
    args = parser.parse_args()
    result = asyncio.run(main(args.samples, args.seconds))
    print_table(result)
    RESULTS.parent.mkdir(parents=True, exist_ok=True)
    RESULTS.write_text(json.dumps(result, indent=2) + "\n")
    print(f"wrote {RESULTS}")
