#!/usr/bin/env bash
# Set up everything the tests need on a fresh machine, then run the whole test suite.
set -euo pipefail
cd "$(dirname "$0")/.."
bash scripts/bootstrap.sh
bash scripts/system-deps.sh
# real footage for the tests that decode vtest.avi; they skip with a reason if it cannot be fetched
bash scripts/fetch-vtest.sh >/dev/null 2>&1 || echo "note: data/vtest.avi could not be fetched; its tests will be skipped"
exec .venv/bin/python -m pytest -q "$@"
