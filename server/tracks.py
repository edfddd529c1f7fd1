"""The competition's tracks (kept apart from the models so the CLI can name them cheaply)."""

from __future__ import annotations

from enum import StrEnum


class Track(StrEnum):
    """Driving SMARTS tracks: any method, or offline learning from recorded data only."""

    freestyle = "freestyle"
    offline = "offline"
