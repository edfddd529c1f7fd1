"""The environment of every process we start: built from an allow-list, never copied.

A child inherits nothing by default here: :func:`child_environment` starts from an empty mapping,
adds ``PATH``, the variables the caller sets and the host's values of the variables it names, and
refuses any variable that holds a secret (``Settings.secret_env_names``), however it is asked
for. Every spawn of the code base builds its environment with it: the sandboxes (agent, warm
parent, intake, training, resolver), the tools a suite build runs (netconvert, SUMO), `arena up`'s
service processes, the training environments' workers. The secrets themselves reach the
processes that need them as files (``ARENA_<FIELD>_FILE``), which the sandboxes never bind.
"""

from __future__ import annotations

import fnmatch
import os
from collections.abc import Iterable, Mapping

from arena.config import Settings
from arena.errors import ArenaError

# What a host tool (netconvert, sumo, pip, our own CLI) needs to find its files and speak UTF-8.
HOST_TOOL_VARIABLES = (
    "PATH",
    "HOME",
    "LANG",
    "LC_ALL",
    "TMPDIR",
    "SUMO_HOME",
    "VIRTUAL_ENV",
    "PYTHONPATH",
)
# What a package-index client (pip, debootstrap) needs to reach the index the host is configured
# for: its proxies, certificates and pip's own settings.
PACKAGE_INDEX_VARIABLES = (
    "http_proxy",
    "https_proxy",
    "no_proxy",
    "HTTP_PROXY",
    "HTTPS_PROXY",
    "NO_PROXY",
    "SSL_CERT_FILE",
    "SSL_CERT_DIR",
    "REQUESTS_CA_BUNDLE",
    "PIP_*",
)
# What our own service processes (`arena up`'s API and worker) need besides: every settings
# variable but the secrets (the secrets' *_FILE variables included), the Docker client's.
SERVICE_VARIABLES = (
    *HOST_TOOL_VARIABLES,
    "USER",
    "LOGNAME",
    "DOCKER_HOST",
    "DOCKER_CONFIG",
    "DOCKER_CERT_PATH",
    "DOCKER_TLS_VERIFY",
    "ARENA_*",
)


class SecretPassedOn(ArenaError, ValueError):
    """A caller asked to pass a secret's variable to a child: a bug of ours, never a team's."""


def child_environment(
    variables: Mapping[str, str] | None = None, *, inherit: Iterable[str] = ()
) -> dict[str, str]:
    """A child's whole environment: ``PATH`` (the system default unless inherited or set),
    the host's values of the variables ``inherit`` names (a trailing ``*`` names a prefix:
    ``PIP_*``), then ``variables``. A secret's variable is refused when named or set, and
    skipped when a prefix covers it."""
    secrets = Settings.secret_env_names()
    variables = dict(variables or {})
    named = [pattern for pattern in inherit if not pattern.endswith("*")]
    refused = sorted(secrets.intersection([*named, *variables]))
    if refused:
        raise SecretPassedOn(f"a child never gets a secret's variable: {', '.join(refused)}")
    prefixes = [pattern for pattern in inherit if pattern.endswith("*")]
    env = {"PATH": os.defpath}
    for name, value in os.environ.items():
        wanted = name in named or any(fnmatch.fnmatchcase(name, p) for p in prefixes)
        if wanted and name not in secrets:
            env[name] = value
    env.update(variables)
    return env
