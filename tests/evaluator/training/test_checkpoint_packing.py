"""Issue 40: a training's output folder is packed (checkpoints while ``train.py`` runs, the model
when it ended) without following a link it holds or swaps in, streamed, and capped in apparent
bytes while it is packed."""

from __future__ import annotations

import multiprocessing
import os
import tarfile
import time
import tracemalloc
from pathlib import Path

import pytest

from evaluator.training import checkpoint
from evaluator.training.checkpoint import CheckpointWatch, SnapshotFailed
from evaluator.training.model import PackRefused, pack_model

MiB = 1024**2
HOST_SECRET = b"host-only secret, never in a team's archive\n"


def packed_bytes(archive: Path) -> bytes:
    with tarfile.open(archive, "r:gz") as tar:
        return b"".join(tar.extractfile(m).read() for m in tar.getmembers() if m.isfile())


def swap_forever(folder: str, target: str) -> None:
    """Flip ``folder/z.bin`` between a file of the team's and a link to ``target``."""
    link, real = os.path.join(folder, "link.tmp"), os.path.join(folder, "real.tmp")
    while True:
        with open(real, "wb") as handle:
            handle.write(b"team bytes\n")
        os.rename(real, os.path.join(folder, "z.bin"))
        os.symlink(target, link)
        os.rename(link, os.path.join(folder, "z.bin"))


# A race run for 4 s with a process swapping the file on the other core: slow, so integration.
@pytest.mark.slow
def test_a_file_swapped_for_a_link_is_never_followed(tmp_path: Path) -> None:
    secret = tmp_path / "host" / "secret.txt"
    secret.parent.mkdir()
    secret.write_bytes(HOST_SECRET)
    output = tmp_path / "output"
    output.mkdir()
    # Files packed before z.bin widen the window between the listing and the opening.
    for number in range(100):
        (output / f"a{number:03}.bin").write_bytes(os.urandom(4096))
    swapper = multiprocessing.get_context("fork").Process(
        target=swap_forever, args=(str(output), str(secret)), daemon=True
    )
    swapper.start()
    try:
        deadline, packs = time.monotonic() + 4, 0
        while time.monotonic() < deadline:
            archive = tmp_path / f"pack-{packs}.tar.gz"
            try:
                pack_model(output, archive)
            except (OSError, PackRefused):
                continue  # z.bin changed under the packing: refused, nothing stored
            packs += 1
            assert HOST_SECRET not in packed_bytes(archive), f"followed a link on pack {packs}"
            archive.unlink()
    finally:
        swapper.kill()
        swapper.join()
    assert packs > 10


def test_links_and_hard_links_in_the_folder_are_not_packed(tmp_path: Path) -> None:
    secret = tmp_path / "secret.txt"
    secret.write_bytes(HOST_SECRET)
    output = tmp_path / "output"
    (output / "sub").mkdir(parents=True)
    (output / "weights.bin").write_bytes(b"w")
    (output / "link").symlink_to(secret)
    (output / "sub" / "folder-link").symlink_to(tmp_path, target_is_directory=True)
    os.link(secret, output / "hard.txt")
    archive = tmp_path / "model.tar.gz"
    pack_model(output, archive)
    with tarfile.open(archive, "r:gz") as tar:
        assert [m.name for m in tar.getmembers()] == ["weights.bin"]


def test_a_sparse_file_is_streamed_and_counted_by_its_apparent_size(tmp_path: Path) -> None:
    output = tmp_path / "output"
    output.mkdir()
    with (output / "sparse.bin").open("wb") as handle:
        handle.truncate(64 * MiB)  # 64 MiB to read, next to nothing on disk
    assert (output / "sparse.bin").stat().st_blocks * 512 < MiB
    with pytest.raises(PackRefused):
        pack_model(output, tmp_path / "capped.tar.gz", max_bytes=32 * MiB)
    assert not (tmp_path / "capped.tar.gz").exists()
    tracemalloc.start()
    try:
        pack_model(output, tmp_path / "model.tar.gz", max_bytes=64 * MiB)
        _, peak = tracemalloc.get_traced_memory()
    finally:
        tracemalloc.stop()
    assert peak < 8 * MiB, f"packing held {peak / MiB:.0f} MiB"


def test_a_folder_grown_past_the_cap_after_it_was_measured_is_not_saved(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    """The snapshot's cap holds while it packs, not only when it measured: the folder grows by a
    sparse 512 MiB file right after the measure (the timing of a training that writes then)."""
    output = tmp_path / "output"
    output.mkdir()
    (output / "small.bin").write_bytes(b"x")
    watch = CheckpointWatch(output, interval_s=1, max_bytes=MiB, max_entries=100)
    assert watch.snapshot(tmp_path / "first.tar.gz")
    measure = checkpoint.output_usage

    def measure_then_grow(folder: Path, max_entries: int):
        usage = measure(folder, max_entries)
        with (output / "grown.bin").open("wb") as handle:
            handle.truncate(512 * MiB)
        return usage

    monkeypatch.setattr(checkpoint, "output_usage", measure_then_grow)
    with pytest.raises(SnapshotFailed):
        watch.snapshot(tmp_path / "second.tar.gz")
    assert not (tmp_path / "second.tar.gz").exists()
