"""Builders of submission zips, good and hostile."""

from __future__ import annotations

import gzip
import io
import warnings
import zipfile
from pathlib import Path

GOOD_POLICY = """
class Policy:
    def act(self, obs):
        return {agent_id: [10.0, 0.0] for agent_id in obs}
"""


def entry(name: str, mode: int = 0o100644) -> zipfile.ZipInfo:
    info = zipfile.ZipInfo(name, date_time=(1980, 1, 1, 0, 0, 0))
    info.external_attr = mode << 16
    info.compress_type = zipfile.ZIP_DEFLATED
    return info


def zip_bytes(files: dict[str | zipfile.ZipInfo, bytes | str]) -> bytes:
    buffer = io.BytesIO()
    with (
        zipfile.ZipFile(buffer, "w", compression=zipfile.ZIP_DEFLATED) as archive,
        warnings.catch_warnings(),
    ):
        warnings.simplefilter("ignore", UserWarning)  # duplicate names are a hostile case
        for name, data in files.items():
            archive.writestr(name if isinstance(name, zipfile.ZipInfo) else entry(name), data)
    return buffer.getvalue()


def write_zip(path: Path, files: dict[str | zipfile.ZipInfo, bytes | str]) -> Path:
    path.write_bytes(zip_bytes(files))
    return path


def with_policy(**extra: bytes | str) -> dict:
    return {"policy.py": GOOD_POLICY, **extra}


def gzip_bytes(data: bytes) -> bytes:
    return gzip.compress(data, compresslevel=9)


def bad_crc_zip(files: dict[str, bytes | str]) -> bytes:
    """A zip whose last entry is stored uncompressed with one data byte flipped: the directory
    is intact, reading the entry fails its CRC check."""
    buffer = io.BytesIO()
    with zipfile.ZipFile(buffer, "w", compression=zipfile.ZIP_STORED) as archive:
        for name, data in files.items():
            archive.writestr(entry(name), data, compress_type=zipfile.ZIP_STORED)
    raw = bytearray(buffer.getvalue())
    last = list(files.values())[-1]
    last = last.encode() if isinstance(last, str) else last
    at = raw.rfind(last)
    raw[at] ^= 0xFF
    return bytes(raw)


def renamed_entry_zip(files: dict[str, bytes | str], placeholder: str, stored: bytes) -> bytes:
    """A zip whose entry ``placeholder`` is stored under the raw name ``stored`` (in its local
    header and the directory): a name zipfile itself cannot write, such as one holding a NUL."""
    raw = zip_bytes(files)
    assert len(stored) == len(placeholder.encode()), "the records keep their lengths"
    return raw.replace(placeholder.encode(), stored)
