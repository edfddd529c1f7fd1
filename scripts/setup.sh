#!/usr/bin/env bash
# Installs what Driving Arena needs on a fresh Debian machine (idempotent, fast when done).
#   scripts/setup.sh           the project and the agent sandbox (bubblewrap; Docker when possible)
#   scripts/setup.sh --dev     also test tools (pytest, ruff, Playwright + Debian's Chromium,
#                              docker-compose)
set -euo pipefail
cd "$(dirname "$0")/.."

dev=0
[ "${1:-}" = "--dev" ] && dev=1

need_apt=()
command -v bwrap >/dev/null || need_apt+=(bubblewrap)
# The simulator's compiled core (setup.py): a C compiler and Python's headers.
command -v gcc >/dev/null || need_apt+=(gcc libc6-dev)
python3 -c 'import os, sys, sysconfig; sys.exit(not os.path.isfile(os.path.join(sysconfig.get_paths()["include"], "Python.h")))' \
  || need_apt+=(python3-dev)
if [ "$dev" = 1 ]; then
  command -v chromium >/dev/null || need_apt+=(chromium)
  # docker-compose.yml's checks and bench/deploy_compose.py (the compose deployment).
  command -v docker-compose >/dev/null || need_apt+=(docker-compose)
fi
if [ "${#need_apt[@]}" -gt 0 ]; then
  if [ "$(id -u)" = 0 ]; then
    apt-get update -qq
    DEBIAN_FRONTEND=noninteractive apt-get install -y -qq "${need_apt[@]}" >/dev/null
  else
    echo "Please install: ${need_apt[*]} (needs root)" >&2
  fi
fi

extras=""
[ "$dev" = 1 ] && extras="[dev,learn]"
# The [learn] extra's stable-baselines3 needs torch: the CPU build first, or pip would resolve a
# multi-GB GPU build.
if [ "$dev" = 1 ]; then
  python3 -m pip install -q --disable-pip-version-check "torch==2.13.0"
fi
python3 -m pip install -q --disable-pip-version-check -e ".${extras}"
python3 -c 'from sim.compiled import core_status; print("simulator core:", core_status())'

# The Docker sandbox: engine, daemon and the offline-built agent image (skipped where impossible).
if [ -x scripts/setup-sandbox.sh ]; then
  scripts/setup-sandbox.sh
fi
