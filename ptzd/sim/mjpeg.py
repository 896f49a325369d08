"""MJPEG over HTTP (multipart/x-mixed-replace), the way cheap IP cameras stream.

`cv2.VideoCapture("http://HOST:PORT/video.mjpg")` opens it. Every part carries the frame's
capture time in an `X-Timestamp` header (seconds on the simulator's clock: CLOCK_MONOTONIC
under the real clock, comparable with `time.monotonic()` of any process on the same host) and
its frame number in `X-Frame`. Each client gets the newest frame when it is ready for one: a
slow client skips frames and never makes the camera or other clients wait.
"""

from __future__ import annotations

import asyncio
import contextlib

import cv2
import numpy as np
import numpy.typing as npt

from ptzd.logs import get_logger
from ptzd.sim.camera import SimFrame

BOUNDARY = "ptzdframe"
STREAM_PATHS = ("/", "/video.mjpg", "/video")

_log = get_logger("sim.mjpeg")


class MjpegServer:
    """Streams the frames given to `publish` to every connected HTTP client."""

    def __init__(self, host: str, port: int, *, quality: int = 85) -> None:
        self._host = host
        self._port = port
        self._quality = quality
        self._server: asyncio.Server | None = None
        self._clients = 0
        self._part: bytes | None = None
        self._new_part = asyncio.Event()
        self.url = ""
        self.frames_encoded = 0
        # a stalled encoder (soak fault `stream-stall`): frames are rendered, none are sent
        self.paused = False

    async def start(self) -> str:
        """Listen; returns the stream URL (with the real port when 0 was asked for)."""
        self._server = await asyncio.start_server(self._serve, self._host, self._port)
        host, port = self._server.sockets[0].getsockname()[:2]
        self.url = f"http://{host}:{port}/video.mjpg"
        _log.info("mjpeg_listen", url=self.url)
        return self.url

    def stall(self, paused: bool) -> None:
        """Stop sending frames (`paused`) or send them again; clients stay connected."""
        self.paused = paused
        _log.warning("mjpeg_stalled" if paused else "mjpeg_resumed")

    def publish(self, frame: SimFrame) -> None:
        """Encode `frame` once (only if someone is watching) and wake every client."""
        if not self._clients or self.paused:
            return
        data = encode_jpeg(frame.image, self._quality)
        if data is None:
            _log.warning("jpeg_encode_failed", frame=frame.index)
            return
        self.frames_encoded += 1
        header = (
            f"--{BOUNDARY}\r\nContent-Type: image/jpeg\r\nContent-Length: {len(data)}\r\n"
            f"X-Timestamp: {frame.t:.6f}\r\nX-Frame: {frame.index}\r\n\r\n"
        ).encode()
        self._part = header + data + b"\r\n"
        event, self._new_part = self._new_part, asyncio.Event()
        event.set()

    async def _serve(self, reader: asyncio.StreamReader, writer: asyncio.StreamWriter) -> None:
        try:
            request = await reader.readuntil(b"\r\n\r\n")
        except (asyncio.IncompleteReadError, asyncio.LimitOverrunError, ConnectionError):
            writer.close()
            return
        parts = request.split(b"\r\n", 1)[0].split()
        path = parts[1].decode(errors="replace").split("?", 1)[0] if len(parts) >= 2 else ""
        if len(parts) < 2 or parts[0] != b"GET" or path not in STREAM_PATHS:
            writer.write(b"HTTP/1.0 404 Not Found\r\nContent-Length: 0\r\n\r\n")
            with contextlib.suppress(ConnectionError):
                await writer.drain()
            writer.close()
            return
        writer.write(
            b"HTTP/1.0 200 OK\r\nCache-Control: no-cache\r\nConnection: close\r\n"
            b"Content-Type: multipart/x-mixed-replace; boundary=" + BOUNDARY.encode() + b"\r\n\r\n"
        )
        self._clients += 1
        try:
            while True:
                await self._new_part.wait()
                if self._part is not None:
                    writer.write(self._part)
                    await writer.drain()
        except ConnectionError:
            pass
        finally:
            self._clients -= 1
            writer.close()

    async def close(self) -> None:
        if self._server is not None:
            self._server.close()
            if hasattr(self._server, "close_clients"):
                self._server.close_clients()
            with contextlib.suppress(Exception):
                await asyncio.wait_for(self._server.wait_closed(), 2.0)
            self._server = None


def encode_jpeg(image: npt.NDArray[np.uint8], quality: int) -> bytes | None:
    """`image` as JPEG at `quality` (None if OpenCV cannot encode it)."""
    ok, jpeg = cv2.imencode(".jpg", image, [cv2.IMWRITE_JPEG_QUALITY, quality])
    return jpeg.tobytes() if ok else None


def jpeg_round_trip(image: npt.NDArray[np.uint8], quality: int) -> npt.NDArray[np.uint8]:
    """`image` JPEG-coded at `quality` and decoded: what this camera's stream delivers
    (chroma subsampled 4:2:0, blocking), for the in-process simulator (`[sim]
    compress_frames`)."""
    data = encode_jpeg(image, quality)
    if data is None:  # pragma: no cover - OpenCV encodes any uint8 image
        raise ValueError(f"cannot JPEG-encode an image of shape {image.shape}")
    flags = cv2.IMREAD_GRAYSCALE if image.ndim == 2 else cv2.IMREAD_COLOR
    decoded = cv2.imdecode(np.frombuffer(data, np.uint8), flags)
    if decoded is None:  # pragma: no cover - it decodes what it has just encoded
        raise ValueError("cannot decode the JPEG just encoded")
    return np.asarray(decoded, dtype=np.uint8)
