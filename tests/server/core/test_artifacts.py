"""The artifact store's two backends behave alike: the data folder and the database."""

from __future__ import annotations

import hashlib

import pytest

from server.core.artifacts import DatabaseStore, FolderStore, MissingArtifact


@pytest.fixture(params=["folder", "database"])
def store(request, db, tmp_path):
    return FolderStore(tmp_path / "root") if request.param == "folder" else DatabaseStore(db)


def test_put_fetch_read_and_replace(store, tmp_path):
    source = tmp_path / "upload.zip"
    source.write_bytes(b"\x00zip bytes\xff" * 1000)
    digest = store.put("submissions/abc/upload.zip", source)
    assert digest == hashlib.sha256(source.read_bytes()).hexdigest()
    assert store.exists("submissions/abc/upload.zip")
    copy = store.fetch("submissions/abc/upload.zip", tmp_path / "elsewhere" / "copy.zip")
    assert copy.read_bytes() == source.read_bytes()
    source.write_bytes(b"new")
    store.put("submissions/abc/upload.zip", source)
    assert store.read("submissions/abc/upload.zip") == b"new"


def test_missing_keys_and_prefix_removal(store, tmp_path):
    source = tmp_path / "record.npz"
    source.write_bytes(b"record")
    for key in ("runs/1/claim-1/a.npz", "runs/1/claim-2/a.npz", "runs/10/claim-1/a.npz"):
        store.put(key, source)
    assert store.delete_prefix("runs/1/") == 2
    assert not store.exists("runs/1/claim-1/a.npz")
    assert store.exists("runs/10/claim-1/a.npz")
    with pytest.raises(MissingArtifact):
        store.read("runs/1/claim-1/a.npz")


@pytest.mark.parametrize("key", ["/etc/passwd", "../outside", "runs/../../x", ""])
def test_keys_cannot_leave_the_store(store, tmp_path, key):
    source = tmp_path / "f"
    source.write_bytes(b"x")
    with pytest.raises(ValueError, match="not an artifact key"):
        store.put(key, source)
