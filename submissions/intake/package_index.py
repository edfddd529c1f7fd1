"""Where a submission's requirements resolve from: the package index the host's pip is configured
for, or the ``package_index`` setting; never a host name of ours.

Only the index's location is taken from the host's configuration (``index-url``,
``extra-index-url``, ``no-index``, ``find-links``, ``cert``): its constraints and other options
are the host's business, not the sandbox's (a host constraint once turned a missing wheel into an
unexplained ``ResolutionImpossible``).
"""

from __future__ import annotations

import functools
import os
import subprocess
import sys
from dataclasses import dataclass, field
from pathlib import Path
from urllib.parse import urlsplit

from arena.config import IntakeSettings

# What `pip config list` reads besides its files: its own variables and where the files are.
PIP_CONFIG_VARIABLES = ("HOME", "XDG_CONFIG_HOME", "XDG_CONFIG_DIRS", "VIRTUAL_ENV")
# How pip's configuration spells a flag that is on (pip's strtobool).
PIP_TRUE = ("1", "true", "yes", "on", "y", "t")


@dataclass(frozen=True)
class PackageSources:
    """Index URLs (the first is pip's index), wheel folders or pages (``find-links``), and the
    certificate bundle pip checks HTTPS with."""

    index_urls: tuple[str, ...] = ()
    find_links: tuple[str, ...] = ()
    cert: str | None = None
    # Hosts the index serves its files from besides its own (pip's default index does).
    file_hosts: tuple[str, ...] = field(default=())

    def folders(self) -> list[Path]:
        """The host folders pip reads: ``file:`` indexes (with their parent, where a simple
        index keeps its files) and wheel folders."""
        found = []
        for url in self.index_urls:
            path = local_path(url)
            if path is not None:
                found.append(path.parent)
        for link in self.find_links:
            path = local_path(link)
            if path is not None:
                found.append(path if path.is_dir() else path.parent)
        if self.cert:
            found.append(Path(self.cert).parent)
        return found


def local_path(location: str) -> Path | None:
    """The folder a ``file:`` URL or a plain path names; None for a web address."""
    parts = urlsplit(location)
    if parts.scheme == "file":
        return Path(parts.path)
    if not parts.scheme and location.startswith("/"):
        return Path(location)
    return None


def package_sources(intake: IntakeSettings) -> PackageSources:
    """The ``package_index`` setting (URLs are indexes, folders wheel folders), else the host's
    pip configuration."""
    if not intake.package_index:
        return host_pip_sources()
    urls = tuple(s for s in intake.package_index if local_path(s) is None)
    folders = tuple(s for s in intake.package_index if local_path(s) is not None)
    return PackageSources(index_urls=urls, find_links=folders)


@functools.cache
def host_pip_sources() -> PackageSources:
    """What the host's pip is configured to install from (`pip config list`: its files and its
    variables; pip's default index when none names one)."""
    listed = subprocess.run(
        [sys.executable, "-m", "pip", "config", "list"],
        env={
            "PATH": os.defpath,
            **{
                name: value
                for name, value in os.environ.items()
                if name in PIP_CONFIG_VARIABLES or name.startswith("PIP_")
            },
        },
        capture_output=True,
        text=True,
        timeout=60,
        check=False,
    ).stdout
    values: dict[str, str] = {}
    for line in listed.splitlines():
        key, equals, value = line.partition("=")
        if equals:
            # Later sources override earlier ones (files, then variables), as pip reads them.
            values[key.rpartition(".")[2]] = value.strip().strip("'\"")
    find_links = tuple(values.get("find-links", "").split())
    cert = values.get("cert") or None
    if values.get("no-index", "").lower() in PIP_TRUE:
        # Wheel folders only, as the host's pip installs (the offline service image's /wheels):
        # pip's default index in its place would be a host it never reaches.
        return PackageSources(find_links=find_links, cert=cert)
    index = values.get("index-url")
    file_hosts: tuple[str, ...] = ()
    if not index:
        # deferred: only where the host names no index of its own
        from pip._internal.models.index import PyPI

        index, file_hosts = PyPI.simple_url, (PyPI.file_storage_domain,)
    extra = values.get("extra-index-url", "").split()
    return PackageSources(
        index_urls=(index, *extra),
        find_links=find_links,
        cert=cert,
        file_hosts=file_hosts,
    )
