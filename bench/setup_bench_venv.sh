#!/usr/bin/env bash
# Create (or refresh) .venv-bench: the benchmark environment with OpenCV's contrib trackers
# (CSRT, KCF, MIL). It holds opencv-contrib-python-headless INSTEAD of the project's
# opencv-python-headless: both ship the `cv2` package and must never share an environment,
# so ptzd is installed with --no-deps and its other runtime dependencies are listed here.
# Idempotent: a second run only re-checks the installs.
set -euo pipefail
cd "$(dirname "$0")/.."
PYTHON=${PYTHON:-python3}
venv=.venv-bench
if [ ! -x "$venv/bin/python" ]; then
  "$PYTHON" -m venv "$venv"
  "$venv/bin/python" -m pip install --quiet --upgrade pip
fi
pip=("$venv/bin/python" -m pip install --quiet)
if "$venv/bin/python" -m pip show opencv-python-headless >/dev/null 2>&1; then
  echo "removing opencv-python-headless from $venv (it clashes with the contrib build)" >&2
  "$venv/bin/python" -m pip uninstall --quiet -y opencv-python-headless
fi
"${pip[@]}" "opencv-contrib-python-headless>=4.8" "numpy>=1.26" "matplotlib>=3.7" \
  "pydantic>=2.6,<3" "structlog>=24.1" "pyserial>=3.5" "scikit-learn>=1.3"
"${pip[@]}" --no-deps -e .
"$venv/bin/python" - <<'PY'
import cv2
names = ("TrackerCSRT", "TrackerKCF", "TrackerMIL")
missing = [n for n in names if not hasattr(cv2, n) and not hasattr(getattr(cv2, "legacy", None), n)]
if missing:
    raise SystemExit(f"cv2 {cv2.__version__} lacks {missing}: is opencv-contrib installed?")
print(f".venv-bench: cv2 {cv2.__version__} with CSRT, KCF, MIL")
PY
