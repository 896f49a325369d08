#!/usr/bin/env bash
# Fetch vtest.avi (pedestrians, static camera, 768x576, 10 fps) from Debian's opencv-doc
# package into data/vtest.avi. Videos are never committed; this script is how you get it.
# Prints the path. Needs apt-get (Debian/Ubuntu); works without root.
set -euo pipefail
cd "$(dirname "$0")/.."
out=data/vtest.avi
if [ -s "$out" ]; then echo "$out"; exit 0; fi
mkdir -p data
work=$(mktemp -d)
trap 'rm -rf "$work"' EXIT
( cd "$work" && apt-get download opencv-doc >/dev/null 2>&1 ) || {
  [ "$(id -u)" = 0 ] && apt-get update -qq >/dev/null && ( cd "$work" && apt-get download opencv-doc >/dev/null )
}
dpkg -x "$work"/opencv-doc_*.deb "$work/x"
cp "$work/x/usr/share/doc/opencv-doc/examples/data/vtest.avi" "$out"
echo "$out"
