"""Real service processes for the tests (:mod:`server.processes`), and the settings exported to
this process as a worker reads them."""

from __future__ import annotations

import os

from arena.config import Settings
from server.processes import ARENA, api_server, environment, free_port, peak_rss_bytes, start, stop


def export_settings(monkeypatch, settings: Settings) -> None:
    """The settings as this process's ARENA_* variables, as :func:`environment` gives a child:
    the process then reads them as ``arena`` commands and workers do (clear ``get_settings``)."""
    for name in [name for name in os.environ if name.startswith("ARENA_")]:
        monkeypatch.delenv(name)
    for name, value in environment(settings).items():
        if name.startswith("ARENA_"):
            monkeypatch.setenv(name, value)


__all__ = ["ARENA", "api_server", "environment", "free_port", "peak_rss_bytes", "start", "stop"]
