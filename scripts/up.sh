#!/usr/bin/env bash
# Sets up a fresh machine and starts the service on its embedded default (SQLite, no Redis).
set -euo pipefail
cd "$(dirname "$0")/.."
scripts/setup.sh
exec arena up "$@"
