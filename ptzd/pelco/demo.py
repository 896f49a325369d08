"""`ptzd pelco demo`: a `PelcoLink` drives one end of a raw pty; the other end decodes.

A short scripted motion sequence (pan, tilt, zoom, a preset, a burst that the link coalesces,
then silence until the dead-man STOP) goes through the real link and a real pseudo-terminal;
every frame that arrives is printed with its arrival time. Bounded by `seconds`.
"""

from __future__ import annotations

import asyncio
import json
import os
import tty

from ptzd.clock import RealClock
from ptzd.pelco.codec import FrameParser, Motion, Preset, PresetAction, Zoom, frame_to_dict
from ptzd.pelco.config import SerialConfig
from ptzd.pelco.link import PelcoLink

# (seconds from start, command)
SCRIPT: tuple[tuple[float, Motion | Preset], ...] = (
    (0.3, Motion(pan=20)),
    (0.8, Motion(pan=-40, tilt=10)),
    (1.3, Motion(zoom=Zoom.IN)),
    (1.8, Motion()),
    (2.0, Preset(PresetAction.SET, 1)),
    (2.2, Motion(pan=64)),
    (2.6, Preset(PresetAction.GOTO, 1)),
)
BURST_AT = 2.8  # 20 motions within 10 ms: only the newest reaches the wire
DEADMAN_S = 1.0


async def _demo(seconds: float) -> dict[str, object]:
    master, slave = os.openpty()
    tty.setraw(slave)
    os.set_blocking(master, False)
    loop = asyncio.get_running_loop()
    parser = FrameParser()
    clock = RealClock()
    start = clock.now()

    def readable() -> None:
        try:
            data = os.read(master, 4096)
        except BlockingIOError:
            return
        for frame in parser.feed(data):
            line = {"t": round(clock.now() - start, 3), **frame_to_dict(frame)}
            print(json.dumps(line), flush=True)

    loop.add_reader(master, readable)
    config = SerialConfig(port=os.ttyname(slave), deadman_s=DEADMAN_S, keepalive_s=0.5)
    try:
        async with PelcoLink(config, clock=clock, seed=0) as link:
            for at, command in SCRIPT:
                if at >= seconds:
                    break
                await asyncio.sleep(max(0.0, start + at - clock.now()))
                link.send(command)
            if seconds > BURST_AT:
                await asyncio.sleep(max(0.0, start + BURST_AT - clock.now()))
                for speed in range(1, 21):
                    link.send(Motion(tilt=-speed))
                    await asyncio.sleep(0.0005)
            # then silence: the dead-man stops the dome after DEADMAN_S
            await asyncio.sleep(max(0.0, start + seconds - clock.now()))
            counters = dict(vars(link.counters))
        await asyncio.sleep(0.1)  # let the closing STOPs arrive
    finally:
        loop.remove_reader(master)
        os.close(master)
        os.close(slave)
    return counters


def run_demo(seconds: float) -> int:
    counters = asyncio.run(_demo(seconds))
    print(json.dumps({"link_counters": counters}), flush=True)
    return 0
