"""The MQTT bridge: track state out, commands in, availability by last will.

`MqttBridge` is an async context manager owning one background TaskGroup with the
connection loop; while connected the loop runs a publisher and a command reader.
Nothing the daemon calls ever waits on the network:

- `publish_track(msg)` keeps only the newest message and the publisher sends at most
  `track_rate_hz` of them (older ones are coalesced, counted in `stats`);
- `set_zoom_layer`, `set_autotrack` (retained) and `set_ptz_state` publish on change;
  retained state is kept and republished on every (re)connect;
- while disconnected, track messages are dropped and counted, and the connection loop
  retries with jittered exponential backoff.

Commands arrive on `<prefix>/<cam>/autotrack/set` and `<prefix>/<cam>/ptz`, are parsed
into typed objects (`ptzd.mqtt.messages`) and delivered through `commands()`, an async
iterator over a bounded queue: when the daemon falls behind, the OLDEST queued command is
dropped (and counted) so the newest (e.g. STOP) always gets through. Rejected payloads
are logged and reported on `<prefix>/<cam>/error`; nothing crashes.
"""

from __future__ import annotations

import asyncio
import contextlib
import dataclasses
import json
import random
import ssl
import time
from collections import deque
from collections.abc import AsyncIterator, Callable, Mapping
from dataclasses import dataclass, field
from types import TracebackType
from typing import Any, Self

import aiomqtt

from ptzd.backoff import backoff_delay
from ptzd.clock import Clock, RealClock
from ptzd.logs import get_logger
from ptzd.mqtt.config import MqttConfig, resolve_password
from ptzd.mqtt.messages import (
    OFFLINE,
    ONLINE,
    Command,
    CommandError,
    PtzState,
    SetAutotrack,
    Topics,
    TrackMessage,
    on_off,
    parse_autotrack,
    parse_ptz,
)

log = get_logger("mqtt")

QOS_STATE = 1  # availability, retained state, discovery: must arrive
QOS_STREAM = 0  # track, ptz/state, error: the next one supersedes a lost one
SHUTDOWN_TIMEOUT_S = 3.0


@dataclass
class BridgeStats:
    """Counters for health reporting and tests."""

    connects: int = 0
    connect_failures: int = 0
    tracks_published: int = 0
    tracks_coalesced: int = 0
    dropped_disconnected: int = 0
    commands_accepted: int = 0
    commands_rejected: int = 0
    commands_dropped: int = 0
    rejected_reasons: list[str] = field(default_factory=list)


class MqttBridge:
    """Connects one camera's daemon to an MQTT broker. See the module docstring."""

    def __init__(
        self,
        config: MqttConfig,
        camera: str,
        *,
        clock: Clock | None = None,
        rng: random.Random | None = None,
        environ: Mapping[str, str] | None = None,
        wall_time: Callable[[], float] = time.time,
    ) -> None:
        self.config = config
        self.camera = camera
        self.topics = Topics(config.prefix, camera)
        self.stats = BridgeStats()
        self._clock: Clock = clock if clock is not None else RealClock()
        self._rng = rng if rng is not None else random.Random()
        self._environ = environ
        self._wall_time = wall_time
        self._retained: dict[str, bytes] = {}  # topic -> payload, republished on connect
        self._outbox: dict[str, tuple[bytes, int, bool]] = {}  # latest-wins per topic
        self._errors: deque[bytes] = deque(maxlen=16)  # each rejection, bounded
        self._track: TrackMessage | None = None
        self._last_track_at = -float("inf")
        self._ptz_state: PtzState | None = None
        self._commands: asyncio.Queue[Command | None] | None = None  # None = closed
        self._wake: asyncio.Event | None = None
        self._stop: asyncio.Event | None = None
        self._connected = False
        self._connected_event: asyncio.Event | None = None
        self._group: asyncio.TaskGroup | None = None
        self._loop_task: asyncio.Task[None] | None = None

    # ------------------------------------------------------------ lifecycle

    async def __aenter__(self) -> Self:
        self._commands = asyncio.Queue(maxsize=self.config.command_queue_size)
        self._wake = asyncio.Event()
        self._stop = asyncio.Event()
        self._connected_event = asyncio.Event()
        password = resolve_password(self.config, self._environ)  # may read a credential file
        self._group = asyncio.TaskGroup()
        await self._group.__aenter__()
        self._loop_task = self._group.create_task(
            self._connection_loop(password.get_secret_value() if password else None),
            name=f"mqtt-connection[{self.camera}]",
        )
        return self

    async def __aexit__(
        self,
        exc_type: type[BaseException] | None,
        exc: BaseException | None,
        tb: TracebackType | None,
    ) -> None:
        assert self._group is not None and self._stop is not None and self._wake is not None
        self._stop.set()
        self._wake.set()
        if self._loop_task is not None:
            # Give the publisher time to send `offline`; a connect attempt in flight is cut.
            done, _ = await asyncio.wait({self._loop_task}, timeout=SHUTDOWN_TIMEOUT_S)
            if not done:
                self._loop_task.cancel()
        self._close_commands()
        await self._group.__aexit__(exc_type, exc, tb)

    @property
    def connected(self) -> bool:
        return self._connected

    async def wait_connected(self) -> None:
        """Wait until the bridge is connected and has republished its retained state."""
        assert self._connected_event is not None, "use inside `async with`"
        await self._connected_event.wait()

    # ------------------------------------------------------------ daemon -> MQTT

    def publish_track(self, msg: TrackMessage) -> None:
        """Queue the newest track message; never blocks. Dropped (and counted) while offline."""
        if not self._connected:
            self.stats.dropped_disconnected += 1
            return
        if self._track is not None:
            self.stats.tracks_coalesced += 1
            if self._track.transitions:  # the state changes survive coalescing
                carried = self._track.transitions + msg.transitions
                msg = dataclasses.replace(msg, transitions=carried)
        self._track = msg
        self._poke()

    def set_zoom_layer(self, layer: int) -> None:
        """Retained integer; published when it changes and on every reconnect."""
        self._set_retained(self.topics.zoom_layer, str(int(layer)).encode())

    def set_autotrack(self, enabled: bool) -> None:
        """Retained ON/OFF; published when it changes and on every reconnect."""
        self._set_retained(self.topics.autotrack_state, on_off(enabled))

    def set_ptz_state(self, pan: int, tilt: int, zoom: int, source: str = "auto") -> None:
        """The last motion command sent to the dome; published (not retained) on change."""
        state = PtzState(pan=pan, tilt=tilt, zoom=zoom, source=source)
        if state == self._ptz_state:
            return
        self._ptz_state = state
        self._send(self.topics.ptz_state, state.to_payload(), QOS_STREAM, retain=False)

    def _set_retained(self, topic: str, payload: bytes) -> None:
        if self._retained.get(topic) == payload:
            return
        self._retained[topic] = payload
        if self._connected:
            self._send(topic, payload, QOS_STATE, retain=True)
        # else: republished by `_on_connect`, not lost

    def _send(self, topic: str, payload: bytes, qos: int, *, retain: bool) -> None:
        if not self._connected:
            self.stats.dropped_disconnected += 1
            return
        self._outbox[topic] = (payload, qos, retain)
        self._poke()

    def _poke(self) -> None:
        if self._wake is not None:
            self._wake.set()

    # ------------------------------------------------------------ MQTT -> daemon

    async def commands(self) -> AsyncIterator[Command]:
        """Parsed commands, oldest first; ends when the bridge closes."""
        assert self._commands is not None, "use inside `async with`"
        while True:
            item = await self._commands.get()
            if item is None:
                return
            yield item

    def _deliver(self, item: Command | None) -> None:
        assert self._commands is not None
        if self._commands.full():
            self._commands.get_nowait()
            self.stats.commands_dropped += 1
            log.warning("mqtt_command_dropped", reason="daemon not keeping up; oldest dropped")
        self._commands.put_nowait(item)

    def _close_commands(self) -> None:
        if self._commands is not None:
            if self._commands.full():
                self._commands.get_nowait()
            self._commands.put_nowait(None)

    def _handle(self, topic: str, payload: bytes, retained: bool) -> None:
        """Parse one incoming message; reject bad ones with a log line and an error message."""
        limit = self.config.max_payload_bytes
        try:
            command: Command
            if topic == self.topics.autotrack_set:
                command = parse_autotrack(topic, payload, max_bytes=limit)
            elif topic == self.topics.ptz:
                if retained:
                    # A retained MOVE_LEFT would restart motion on every reconnect.
                    raise CommandError(topic, "retained PTZ commands are ignored", payload)
                command = parse_ptz(topic, payload, max_bytes=limit)
            else:
                raise CommandError(topic, "not a command topic", payload)
        except CommandError as exc:
            self.stats.commands_rejected += 1
            self.stats.rejected_reasons.append(exc.reason)
            del self.stats.rejected_reasons[:-32]
            log.warning(
                "mqtt_command_rejected",
                topic=exc.topic,
                reason=exc.reason,
                payload_bytes=exc.payload_size,
                payload_preview=exc.preview,
            )
            if self._connected:
                self._errors.append(exc.to_payload(self._wall_time()))
                self._poke()
            else:
                self.stats.dropped_disconnected += 1
            return
        self.stats.commands_accepted += 1
        log.info("mqtt_command", topic=topic, command=repr(command))
        if isinstance(command, SetAutotrack):
            # Acknowledge at once; the daemon may still override with set_autotrack().
            self.set_autotrack(command.enabled)
        self._deliver(command)

    # ------------------------------------------------------------ connection

    def _client(self, password: str | None) -> aiomqtt.Client:
        cfg = self.config
        broker = cfg.broker
        tls_context: ssl.SSLContext | None = None
        if broker.tls:
            tls_context = ssl.create_default_context(
                cafile=str(cfg.ca_file) if cfg.ca_file else None
            )
            if cfg.cert_file is not None and cfg.key_file is not None:
                tls_context.load_cert_chain(str(cfg.cert_file), str(cfg.key_file))
        return aiomqtt.Client(
            broker.host,
            broker.port,
            identifier=cfg.client_id or f"ptzd-{self.camera}",
            username=cfg.username or None,
            password=password,
            keepalive=cfg.keepalive_s,
            timeout=cfg.timeout_s,
            tls_context=tls_context,
            will=aiomqtt.Will(self.topics.availability, OFFLINE, qos=QOS_STATE, retain=True),
            max_queued_incoming_messages=256,
        )

    async def _connection_loop(self, password: str | None) -> None:
        assert self._stop is not None
        attempt = 0
        while not self._stop.is_set():
            try:
                client = self._client(password)
                async with client:
                    attempt = 0
                    self.stats.connects += 1
                    await self._session(client)
            except* aiomqtt.MqttError as group:
                self.stats.connect_failures += 1
                log.warning("mqtt_disconnected", error=str(group.exceptions[0]), attempt=attempt)
            except* (ssl.SSLError, OSError) as group:
                # e.g. unreadable CA / client certificate: retrying may help after a fix
                self.stats.connect_failures += 1
                log.error("mqtt_tls_setup_failed", error=str(group.exceptions[0]))
            finally:
                self._set_connected(False)
            if self._stop.is_set():
                break
            delay = backoff_delay(
                attempt, self.config.reconnect_min_s, self.config.reconnect_max_s, self._rng
            )
            attempt += 1
            log.info("mqtt_reconnect_wait", seconds=round(delay, 3), attempt=attempt)
            await self._sleep_unless_stopped(delay)

    async def _sleep_unless_stopped(self, seconds: float) -> None:
        assert self._stop is not None
        stopped = asyncio.ensure_future(self._stop.wait())
        sleeper = asyncio.ensure_future(self._clock.sleep(seconds))
        try:
            await asyncio.wait({stopped, sleeper}, return_when=asyncio.FIRST_COMPLETED)
        finally:
            stopped.cancel()
            sleeper.cancel()

    def _set_connected(self, value: bool) -> None:
        self._connected = value
        assert self._connected_event is not None
        if value:
            self._connected_event.set()
        else:
            self._connected_event.clear()
            self._track = None
            self._outbox.clear()
            self._errors.clear()

    async def _session(self, client: aiomqtt.Client) -> None:
        """One connection: announce, subscribe, then publish and read until stop or error."""
        assert self._wake is not None
        topics = self.topics
        await client.subscribe(topics.autotrack_set, qos=QOS_STATE)
        await client.subscribe(topics.ptz, qos=QOS_STATE)
        await client.publish(topics.availability, ONLINE, qos=QOS_STATE, retain=True)
        if self.config.discovery:
            for topic, body in self.discovery_messages():
                await client.publish(topic, body, qos=QOS_STATE, retain=True)
        # Connected first, then the retained state: an update racing with these awaits
        # is queued to the outbox and sent after them, so the newest value wins.
        self._connected = True
        self._outbox.clear()
        for topic, payload in list(self._retained.items()):
            await client.publish(topic, payload, qos=QOS_STATE, retain=True)
        self._set_connected(True)
        log.info("mqtt_connected", broker=f"{self.config.broker.host}:{self.config.broker.port}")
        async with asyncio.TaskGroup() as group:
            reader = group.create_task(self._reader(client), name="mqtt-commands")
            group.create_task(self._publisher(client, reader), name="mqtt-publisher")

    async def _reader(self, client: aiomqtt.Client) -> None:
        async for message in client.messages:
            payload = message.payload
            raw = bytes(payload) if isinstance(payload, bytes | bytearray) else b""
            self._handle(str(message.topic), raw, bool(message.retain))

    async def _publisher(self, client: aiomqtt.Client, reader: asyncio.Task[None]) -> None:
        assert self._wake is not None and self._stop is not None
        period = 1.0 / self.config.track_rate_hz
        while True:
            await self._wake.wait()
            self._wake.clear()
            while self._outbox:
                topic = next(iter(self._outbox))
                payload, qos, retain = self._outbox.pop(topic)
                await client.publish(topic, payload, qos=qos, retain=retain)
            while self._errors:
                await client.publish(self.topics.error, self._errors.popleft(), qos=QOS_STREAM)
            if self._stop.is_set():
                break
            if self._track is not None:
                wait = self._last_track_at + period - self._clock.now()
                if wait > 0:
                    await self._clock.sleep(wait)  # newer messages replace it meanwhile
                    self._wake.set()  # re-check outbox and stop first
                    continue
                msg, self._track = self._track, None
                await client.publish(self.topics.track, msg.to_payload(), qos=QOS_STREAM)
                self._last_track_at = self._clock.now()
                self.stats.tracks_published += 1
        # Clean shutdown: say goodbye ourselves (the will only fires on unclean loss).
        await client.publish(self.topics.availability, OFFLINE, qos=QOS_STATE, retain=True)
        self._connected = False
        reader.cancel()

    # ------------------------------------------------------------ Home Assistant

    def discovery_messages(self) -> list[tuple[str, bytes]]:
        """Home Assistant MQTT discovery configs: autotrack switch, state and zoom sensors."""
        topics = self.topics
        node = f"ptzd_{self.camera}"
        device = {
            "identifiers": [node],
            "name": f"ptzd {self.camera}",
            "manufacturer": "ptzd",
            "model": "PTZ auto-tracker",
        }
        common: dict[str, Any] = {
            "availability_topic": topics.availability,
            "payload_available": ONLINE.decode(),
            "payload_not_available": OFFLINE.decode(),
            "device": device,
        }
        prefix = self.config.discovery_prefix
        entities: list[tuple[str, dict[str, Any]]] = [
            (
                f"{prefix}/switch/{node}/autotrack/config",
                {
                    "name": "Autotrack",
                    "unique_id": f"{node}_autotrack",
                    "command_topic": topics.autotrack_set,
                    "state_topic": topics.autotrack_state,
                    "payload_on": "ON",
                    "payload_off": "OFF",
                    "icon": "mdi:cctv",
                },
            ),
            (
                f"{prefix}/sensor/{node}/state/config",
                {
                    "name": "Tracking state",
                    "unique_id": f"{node}_state",
                    "state_topic": topics.track,
                    "value_template": "{{ value_json.state }}",
                    "icon": "mdi:account-search",
                },
            ),
            (
                f"{prefix}/sensor/{node}/zoom_layer/config",
                {
                    "name": "Zoom layer",
                    "unique_id": f"{node}_zoom_layer",
                    "state_topic": topics.zoom_layer,
                    "icon": "mdi:magnify-plus",
                },
            ),
        ]
        return [
            (topic, json.dumps({**body, **common}, separators=(",", ":")).encode())
            for topic, body in entities
        ]


@contextlib.asynccontextmanager
async def optional_bridge(
    config: MqttConfig, camera: str, **kwargs: Any
) -> AsyncIterator[MqttBridge | None]:
    """`MqttBridge` when `config.enabled`, else None: one `async with` for the daemon."""
    if not config.enabled:
        yield None
        return
    async with MqttBridge(config, camera, **kwargs) as bridge:
        yield bridge
