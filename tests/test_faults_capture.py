"""Fault: the camera's live stream is cut (camera reboot, proxy restart) and comes back at
another resolution.

Expected recovery (docs/reliability.md): `VideoCaptureSource` logs `capture_lost`, reopens
the live URL with backoff and keeps yielding frames; the new size simply flows through.
A file that ends still ends the iteration (tests/test_app_capture.py).
"""

from __future__ import annotations

import asyncio
import contextlib

import cv2
import numpy as np

from ptzd.capture import VideoCaptureSource
from ptzd.clock import RealClock

BOUNDARY = b"frame"


def jpeg(width: int, height: int, shade: int) -> bytes:
    image = np.full((height, width, 3), shade, np.uint8)
    ok, data = cv2.imencode(".jpg", image)
    assert ok
    return bytes(data)


class CuttingMjpegServer:
    """multipart/x-mixed-replace over HTTP: each connection gets `per_connection` frames of
    the next size in `sizes`, then the server hangs up."""

    def __init__(self, sizes: list[tuple[int, int]], per_connection: int = 15) -> None:
        self.sizes = sizes
        self.per_connection = per_connection
        self.connections = 0
        self.port = 0
        self.server: asyncio.Server | None = None

    async def start(self) -> None:
        self.server = await asyncio.start_server(self._serve, "127.0.0.1", 0)
        self.port = self.server.sockets[0].getsockname()[1]

    async def _serve(self, reader: asyncio.StreamReader, writer: asyncio.StreamWriter) -> None:
        size = self.sizes[min(self.connections, len(self.sizes) - 1)]
        self.connections += 1
        with contextlib.suppress(ConnectionError):
            await reader.readuntil(b"\r\n\r\n")
            writer.write(
                b"HTTP/1.0 200 OK\r\nContent-Type: multipart/x-mixed-replace; boundary="
                + BOUNDARY
                + b"\r\n\r\n"
            )
            for i in range(self.per_connection):
                data = jpeg(*size, shade=40 + 10 * i)
                writer.write(
                    b"--" + BOUNDARY + b"\r\nContent-Type: image/jpeg\r\n"
                    + f"Content-Length: {len(data)}\r\n\r\n".encode() + data + b"\r\n"
                )  # fmt: skip
                await writer.drain()
                await asyncio.sleep(0.02)
        writer.close()  # the stream is cut

    async def close(self) -> None:
        assert self.server is not None
        self.server.close()


async def test_cut_stream_is_reopened_and_a_new_resolution_flows_through() -> None:
    server = CuttingMjpegServer([(160, 120), (320, 240)])
    await server.start()
    source = VideoCaptureSource(f"http://127.0.0.1:{server.port}/video.mjpg", RealClock())
    sizes: list[tuple[int, int]] = []
    try:
        async with asyncio.timeout(60):
            async for item in source.frames():
                sizes.append((item.image.shape[1], item.image.shape[0]))
                if (320, 240) in sizes and len(sizes) >= 20:
                    break
    finally:
        await server.close()
    assert server.connections >= 2
    assert sizes[0] == (160, 120) and sizes[-1] == (320, 240)
