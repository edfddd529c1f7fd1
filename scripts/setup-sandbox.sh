#!/usr/bin/env bash
# The agent sandbox on a fresh Debian machine: bubblewrap (+ Debian's python3-numpy, the runtime it
# binds), the Docker engine with a running daemon, and the two images built offline: the agent
# runtime and the builder the resolver compiles sdists in (about 2 minutes more on a fresh machine).
# Idempotent; takes about a second when everything is already there. Needs root for apt/dockerd.
#   scripts/setup-sandbox.sh
set -euo pipefail
cd "$(dirname "$0")/.."

log() { echo "setup-sandbox: $*" >&2; }

missing=()
command -v bwrap >/dev/null || missing+=(bubblewrap)
command -v debootstrap >/dev/null || missing+=(debootstrap)
command -v dockerd >/dev/null || missing+=(docker.io)
/usr/bin/python3 -c "import numpy" 2>/dev/null || missing+=(python3 python3-numpy)
if [ "${#missing[@]}" -gt 0 ]; then
  if [ "$(id -u)" != 0 ]; then
    log "please install as root: apt-get install ${missing[*]}"
    exit 1
  fi
  log "installing ${missing[*]}"
  apt-get update -qq
  DEBIAN_FRONTEND=noninteractive apt-get install -y -qq --no-install-recommends "${missing[@]}" >/dev/null
fi

# The daemon: no bridge network and no iptables rules, since agents never get a network anyway.
if ! docker info >/dev/null 2>&1; then
  if [ "$(id -u)" != 0 ]; then
    log "no Docker daemon answers and only root can start one; the Docker sandbox stays unavailable"
    exit 0
  fi
  mkdir -p /var/log
  log "starting dockerd (log: /var/log/dockerd.log)"
  setsid nohup dockerd --bridge=none --iptables=false >/var/log/dockerd.log 2>&1 < /dev/null &
  for _ in $(seq 120); do
    docker info >/dev/null 2>&1 && break
    sleep 0.5
  done
  if ! docker info >/dev/null 2>&1; then
    log "dockerd did not come up; last lines of /var/log/dockerd.log:"
    tail -n 20 /var/log/dockerd.log >&2 || true
    exit 1
  fi
fi

# The agent and builder images (offline: debootstrap + docker import; each root tarball is cached in
# the data dir). The command is idempotent: it only reports an image that is already there.
python3 -c 'from arena_command import app; app()' sandbox build-image
log "ready: bubblewrap, dockerd and both images"
