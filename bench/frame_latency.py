"""Frame latency: from a Pelco pan command on the wire to the first frame that shows it.

This is the value for `[capture] latency_s`: how much older a frame is than its arrival
(exposure, encoding, network, the decoder's buffer), plus the dome's own reaction time. The
daemon dead-reckons the pose of a dome that reports none from the commands it sent; it must
look that pose up at the time a frame was taken, not when it arrived.

Method: frames are read continuously in a thread and stamped on arrival. With the dome still,
a pan command is written to the serial port and its time taken; the first frame whose image
has shifted against the previous one (phase correlation, > `--shift-px`) marks the onset.
Latency = onset arrival - command time. STOP after each trial; trials alternate left and
right. The onset is quantised by the frame period, which the table shows beside it.

Against the simulated dome (default: `ptzd sim-camera --scene synthetic:0`, MJPEG over HTTP
and Pelco over TCP, as in the soak) or a real one: `--source URL --serial PORT`.

Run: .venv/bin/python -m bench.frame_latency [--trials 10] [--source URL --serial PORT]
Writes JSON to bench/results/frame_latency.json.
"""

from __future__ import annotations

import argparse
import contextlib
import itertools
import json
import statistics
import subprocess
import sys
import threading
import time
from collections import deque
from collections.abc import Iterator
from pathlib import Path

import cv2
import numpy as np
import serial

from ptzd.pelco.codec import Motion, PelcoProtocol, encode

RESULTS = Path(__file__).resolve().parent / "results" / "frame_latency.json"


@contextlib.contextmanager
def sim_camera() -> Iterator[tuple[str, str]]:
    """A `ptzd sim-camera` child; yields its (MJPEG URL, socket:// serial URL)."""
    child = subprocess.Popen(
        [sys.executable, "-m", "ptzd", "--log-format", "json", "sim-camera", "--scene",
         "synthetic:0", "--loop", "--serial", "tcp://127.0.0.1:0", "--http", "127.0.0.1:0"],
        stdout=subprocess.PIPE,
        stderr=subprocess.DEVNULL,
    )  # fmt: skip
    try:
        assert child.stdout is not None
        found: dict[str, str] = {}
        while len(found) < 2:
            line = child.stdout.readline().decode()
            if not line:
                raise RuntimeError("sim-camera exited before announcing its endpoints")
            word, _, value = line.strip().partition(" ")
            if word in ("http", "serial"):
                found[word] = value
        yield found["http"], found["serial"]
    finally:
        child.terminate()
        child.wait(timeout=10)


class Frames:
    """Grey frames of `source` with their arrival times (perf_counter), read in a thread;
    the last `keep` only (a trial needs a few seconds, not every frame of the run)."""

    def __init__(self, source: str, keep: int = 250) -> None:
        self.capture = cv2.VideoCapture(source)
        if not self.capture.isOpened():
            raise RuntimeError(f"cannot open {source}")
        self.items: deque[tuple[float, np.ndarray]] = deque(maxlen=keep)
        self._stop = threading.Event()
        self._thread = threading.Thread(target=self._read, name="frames", daemon=True)
        self._thread.start()

    def _read(self) -> None:
        while not self._stop.is_set():
            ok, image = self.capture.read()
            if not ok:
                return
            self.items.append((time.perf_counter(), cv2.cvtColor(image, cv2.COLOR_BGR2GRAY)))

    def close(self) -> None:
        self._stop.set()
        self._thread.join(timeout=5)
        self.capture.release()


def onset(frames: list[tuple[float, np.ndarray]], sent: float, shift_px: float) -> float | None:
    """Seconds from `sent` to the arrival of the first frame shifted against the one before."""
    for (_, before), (arrived, after) in itertools.pairwise(frames):
        (dx, dy), _ = cv2.phaseCorrelate(before.astype(np.float32), after.astype(np.float32))
        if arrived > sent and np.hypot(dx, dy) > shift_px:
            return arrived - sent
    return None


def measure(source: str, port: str, args: argparse.Namespace) -> dict[str, object]:
    frames = Frames(source)
    link = serial.serial_for_url(port, baudrate=args.baud, timeout=1)
    protocol = PelcoProtocol(args.protocol)
    stop = encode(Motion(), protocol=protocol, address=args.address)
    trials: list[dict[str, float | None]] = []
    try:
        link.write(stop)
        time.sleep(args.settle_s)
        for trial in range(args.trials):
            speed = args.speed if trial % 2 == 0 else -args.speed
            link.write(encode(Motion(pan=speed), protocol=protocol, address=args.address))
            link.flush()
            sent = time.perf_counter()
            time.sleep(args.move_s)
            link.write(stop)
            # from the last frame before the command on (the reference for the first shift)
            items = list(frames.items)
            before = [i for i, (t, _) in enumerate(items) if t <= sent]
            seen = items[before[-1] if before else 0 :]
            period = statistics.median(np.diff([t for t, _ in seen])) if len(seen) > 2 else None
            latency = onset(seen, sent, args.shift_px)
            trials.append({"latency_s": latency, "frame_period_s": period})
            shown = "-" if latency is None else f"{1000 * latency:.0f}"
            gap = "-" if period is None else f"{1000 * period:.0f}"
            print(f"trial {trial:2d}  pan {speed:+3d}  onset {shown:>5} ms  frame period {gap} ms")
            time.sleep(args.settle_s)
    finally:
        with contextlib.suppress(serial.SerialException):
            link.write(stop)
        link.close()
        frames.close()
    found = [t["latency_s"] for t in trials if t["latency_s"] is not None]
    return {
        "source": source,
        "serial": port,
        "trials": trials,
        "median_latency_s": round(statistics.median(found), 4) if found else None,
        "min_latency_s": round(min(found), 4) if found else None,
        "max_latency_s": round(max(found), 4) if found else None,
        "missed": len(trials) - len(found),
    }


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--source", help="camera URL (default: a ptzd sim-camera)")
    parser.add_argument("--serial", help="pyserial URL of the dome (with --source)")
    parser.add_argument("--protocol", choices=["p", "d"], default="p")
    parser.add_argument("--address", type=int, default=1)
    parser.add_argument("--baud", type=int, default=4800)
    parser.add_argument("--trials", type=int, default=10)
    parser.add_argument("--speed", type=int, default=40, help="Pelco pan speed of each trial")
    parser.add_argument("--move-s", type=float, default=0.8)
    parser.add_argument("--settle-s", type=float, default=1.5)
    parser.add_argument("--shift-px", type=float, default=0.5)
    parser.add_argument("--out", type=Path, default=RESULTS)
    args = parser.parse_args()
    if (args.source is None) != (args.serial is None):
        parser.error("--source and --serial go together")
    if args.source is None:
        with sim_camera() as (source, port):
            result = measure(source, port, args)
    else:
        result = measure(args.source, args.serial, args)
    median = result["median_latency_s"]
    print(f"\nmedian {median} s over {args.trials - int(result['missed'])} trials"  # type: ignore[call-overload]
          f" (min {result['min_latency_s']}, max {result['max_latency_s']})")  # fmt: skip
    print(f"-> [capture] latency_s = {median}")
    args.out.parent.mkdir(parents=True, exist_ok=True)
    args.out.write_text(json.dumps(result, indent=2) + "\n")
    print(f"wrote {args.out}")


if __name__ == "__main__":
    main()
