#!/bin/sh
# The secret files docker-compose.yml reads (docs/deployment.md, "Secrets"), made once:
#   scripts/compose_secrets.sh [FOLDER]        # default ./secrets (ARENA_SECRETS_DIR)
# Each is 192 random bits, mode 400, owned by the uid that reads it: the API's (1000, the
# service image's `arena` user) for the admin token and the two passwords, root for the hidden
# seed (only the root `suites` one-shot reads it). An existing file is kept: rotating a secret is
# deleting its file first (and, for the database password, changing it in PostgreSQL too).
set -eu
folder="${1:-${ARENA_SECRETS_DIR:-./secrets}}"
api_uid=1000
umask 077
mkdir -p "$folder"
for name in admin_token postgres_password redis_password hidden_seed; do
  path="$folder/$name"
  [ -e "$path" ] && continue
  python3 -c 'import secrets; print(secrets.token_urlsafe(24))' > "$path"
  chmod 400 "$path"
  [ "$name" = hidden_seed ] || chown "$api_uid" "$path"
  echo "made $path"
done
# The Docker daemon binds the files into the containers: their owners must get through.
chmod 711 "$folder"
