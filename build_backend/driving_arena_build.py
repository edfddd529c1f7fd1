"""The project's build backend: setuptools, plus a start-up hook in every wheel.

Gymnasium 1.x no longer loads plugin entry points, so the wheels (regular and editable) carry
``driving_arena_gymnasium.pth`` at the top of ``site-packages``; Python runs it at start-up and it
registers our environments when Gymnasium is imported (``learn/gymnasium_hook.py``). setuptools has
no supported way to put a file there in an editable wheel, hence this thin wrapper (PEP 517
in-tree backend) that adds the file to the wheels setuptools builds and lists it in ``RECORD``.
"""

from __future__ import annotations

import base64
import hashlib
import os
import zipfile
from pathlib import Path

from setuptools import build_meta
from setuptools.build_meta import *  # noqa: F403 (every hook we do not wrap is setuptools')

HOOK = Path(__file__).with_name("driving_arena_gymnasium.pth")


def build_wheel(wheel_directory, config_settings=None, metadata_directory=None):
    name = build_meta.build_wheel(wheel_directory, config_settings, metadata_directory)
    _add_hook(Path(wheel_directory, name))
    return name


def build_editable(wheel_directory, config_settings=None, metadata_directory=None):
    name = build_meta.build_editable(wheel_directory, config_settings, metadata_directory)
    _add_hook(Path(wheel_directory, name))
    return name


def _add_hook(wheel: Path) -> None:
    """Rewrite ``wheel`` with the hook at its root and a ``RECORD`` line for it."""
    data = HOOK.read_bytes()
    digest = base64.urlsafe_b64encode(hashlib.sha256(data).digest()).rstrip(b"=").decode()
    rewritten = wheel.with_suffix(".tmp")
    with (
        zipfile.ZipFile(wheel) as source,
        zipfile.ZipFile(rewritten, "w", zipfile.ZIP_DEFLATED) as target,
    ):
        for item in source.infolist():
            content = source.read(item)
            if item.filename.endswith(".dist-info/RECORD"):
                content += f"{HOOK.name},sha256={digest},{len(data)}\n".encode()
            target.writestr(item, content)
        target.writestr(HOOK.name, data)
    os.replace(rewritten, wheel)
