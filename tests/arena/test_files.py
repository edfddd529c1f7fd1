from __future__ import annotations

import hashlib
import os

import pytest

from arena.files import file_sha256, replaced_atomically, write_atomically


def test_two_writers_of_one_file_interleaved_both_finish_and_the_last_wins(tmp_path):
    # Two workers filling one cache entry at once: neither writes into, or moves away, the
    # other's partial file.
    dest = tmp_path / "cache" / "entry.bin"
    with replaced_atomically(dest) as first:
        first.write_bytes(b"first")
        with replaced_atomically(dest) as second:
            second.write_bytes(b"second")
        assert dest.read_bytes() == b"second"
    assert dest.read_bytes() == b"first"
    assert [p.name for p in dest.parent.iterdir()] == ["entry.bin"]


def test_a_writer_that_fails_leaves_the_old_file_and_no_partial(tmp_path):
    dest = write_atomically(tmp_path / "summary.json", "old\n")
    with pytest.raises(RuntimeError), replaced_atomically(dest) as partial:
        partial.write_text("half")
        raise RuntimeError("the writer crashed")
    assert dest.read_text() == "old\n"
    assert [p.name for p in tmp_path.iterdir()] == ["summary.json"]


def test_the_file_gets_the_umasks_permissions(tmp_path):
    # Sandboxes (another user) read built maps and suites.
    assert (write_atomically(tmp_path / "map.net.xml", b"<net/>").stat().st_mode & 0o777) == (
        0o666 & ~_umask()
    )


def _umask() -> int:
    mask = os.umask(0)
    os.umask(mask)
    return mask


@pytest.mark.parametrize("size", [0, 1, (1 << 20) - 1, 1 << 20, 3 * (1 << 20) + 7])
def test_a_files_digest_is_the_sha256_of_its_bytes_across_chunk_edges(tmp_path, size):
    data = os.urandom(size)
    path = tmp_path / "blob"
    path.write_bytes(data)
    assert file_sha256(path) == hashlib.sha256(data).hexdigest()
