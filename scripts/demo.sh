#!/usr/bin/env bash
# The first demo: the simulated PTZ dome and the daemon, closed over real Pelco bytes on a
# pty, tracking a walker of a synthetic scene live (real time, 40 s). Then: where the
# recording is, and a summary of its report. When mosquitto is installed the run also
# publishes over MQTT to a private broker on a free loopback port, and a few of the
# messages are shown. Bounded: setup, then about a minute.
set -euo pipefail
cd "$(dirname "$0")/.."
bash scripts/bootstrap.sh
PY=.venv/bin/python
OUT=out/demo
rm -rf "$OUT"
mkdir -p "$OUT"

pids=()
cleanup() {
  for pid in "${pids[@]}"; do kill "$pid" 2>/dev/null || true; done
}
trap cleanup EXIT

mqtt_args=()
MOSQUITTO=$(command -v mosquitto || { [ -x /usr/sbin/mosquitto ] && echo /usr/sbin/mosquitto; } || true)
if [ -n "$MOSQUITTO" ]; then
  port=$("$PY" -c 'import socket; s = socket.socket(); s.bind(("127.0.0.1", 0)); print(s.getsockname()[1])')
  conf="$OUT/mosquitto.conf"
  printf 'user %s\nlistener %s 127.0.0.1\nallow_anonymous true\npersistence false\n' \
    "$(id -un)" "$port" > "$conf"
  "$MOSQUITTO" -c "$conf" > "$OUT/mosquitto.log" 2>&1 &
  pids+=($!)
  # the subscriber (aiomqtt, from the venv) connects once the broker listens, then records
  # every message under ptzd/# for at most 90 s
  "$PY" - "$port" > "$OUT/mqtt.log" 2>&1 <<'EOF' &
import asyncio, sys, time
import aiomqtt

async def main(port: int) -> None:
    deadline = time.monotonic() + 10
    while True:
        try:
            async with aiomqtt.Client("127.0.0.1", port) as client:
                await client.subscribe("ptzd/#")
                print("subscribed", flush=True)
                async with asyncio.timeout(90):
                    async for m in client.messages:
                        payload = m.payload.decode(errors="replace") if isinstance(m.payload, bytes) else m.payload
                        print(m.topic, payload, flush=True)
        except aiomqtt.MqttError:
            if time.monotonic() > deadline:
                raise
            await asyncio.sleep(0.2)

try:
    asyncio.run(main(int(sys.argv[1])))
except TimeoutError:
    pass
EOF
  pids+=($!)
  for _ in $(seq 50); do grep -q subscribed "$OUT/mqtt.log" 2>/dev/null && break; sleep 0.2; done
  if grep -q subscribed "$OUT/mqtt.log"; then
    mqtt_args=(--mqtt-url "mqtt://127.0.0.1:$port" --camera-name demo)
    echo "== MQTT: mosquitto on 127.0.0.1:$port (watch live: mosquitto_sub -p $port -v -t 'ptzd/#')"
  else
    echo "== MQTT: mosquitto did not come up (see $OUT/mosquitto.log); running without it"
  fi
fi

echo "== ptzd sim: simulated dome + daemon, synthetic scene 3, 40 s in real time"
timeout 180 .venv/bin/ptzd --log-format console sim --scene synthetic:3 --duration 40 \
  --record "$OUT" --view "$OUT/view.mp4" "${mqtt_args[@]}" > "$OUT/summary.json"

echo
echo "== recording in $OUT/"
echo "   view.mp4     what the dome saw, the tracker's box drawn on it (green: tracking)"
echo "   report.json  report.png (offset, size, FOV and zoom layer over time)"
echo "   camera.jsonl (every rendered view)  track.jsonl (every tracked frame)  serial.jsonl (the Pelco bytes)"
"$PY" - "$OUT/report.json" <<'EOF'
import json, sys

r = json.load(open(sys.argv[1]))

def pct(v):
    return "n/a" if v is None else f"{100 * v:.1f} %"

def ms(v):
    return "n/a" if v is None else f"{v:.1f} ms"

lat = r["latency_ms"]
print("== summary")
print(f"   target centred (central cell of 3x3): {pct(r['centred_fraction'])} of {r['frames_scored']} frames")
print(f"   target in view:                       {pct(r['in_view_fraction'])}")
print(f"   frame-to-command latency p50 / p99:   {ms(lat['p50_ms'])} / {ms(lat['p99_ms'])}")
print(f"   zoom steps: {len(r['zoom_layer_timeline']) - 1}, reversals: {r['zoom_reversals']}, "
      f"frames dropped: {r['frames_dropped']}, Pelco frames sent: {r['link_frames_sent']}")
EOF

if [ ${#mqtt_args[@]} -gt 0 ]; then
  sleep 0.5
  echo "== MQTT (a few of $(grep -c '^ptzd/' "$OUT/mqtt.log" || true) messages; all in $OUT/mqtt.log)"
  for topic in availability autotrack/state zoom_layer ptz/state track; do
    grep -m 2 "^ptzd/demo/$topic " "$OUT/mqtt.log" | cut -c 1-160 | sed 's/^/   /' || true
  done
fi
