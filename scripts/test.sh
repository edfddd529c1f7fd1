#!/usr/bin/env bash
# Sets up a fresh machine (scripts/setup.sh --dev) and runs the whole test suite.
set -euo pipefail
cd "$(dirname "$0")/.."
scripts/setup.sh --dev
ruff check .
lint-imports
python3 -m pytest "$@"
