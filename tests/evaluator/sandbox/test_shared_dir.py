"""A worker in a container (docker-compose.yml) starts agents beside it through the host's
daemon, which binds host paths: with ARENA_SANDBOX_SHARED_DIR every read-only folder outside the
data and the shared folder (the runtime, the resolver's pip, wheel and index folders, the
certificates) is bound as a copy in the shared folder, and the sockets live there, whose path is
the same on both sides. The compose deployment test (tests/server/test_compose_deployment.py)
runs agents and resolvers that way."""

from __future__ import annotations

import os
import shutil
import subprocess
import tempfile
import time
from collections.abc import Iterator
from pathlib import Path

import pytest

from evaluator.sandbox.backend import RUNTIME_MAIN, RUNTIME_MOUNT, LaunchSpec, Training, runtime_dir
from evaluator.sandbox.docker_backend import (
    COPIES_DIR,
    STALE_COPY_AGE_S,
    UNPRIVILEGED_ID,
    container_options,
    remove_stale_copies,
    shared_copy,
    socket_dir_for,
)
from tests.settings import env_only


def binds(options: dict) -> dict[str, tuple[Path, str]]:
    """Where the container sees each bound folder: (the host folder the daemon binds, mode)."""
    return {v["bind"]: (Path(source), v["mode"]) for source, v in options["volumes"].items()}


def same_files(copy: Path, folder: Path) -> bool:
    """``copy`` holds ``folder``'s files but its bytecode caches, byte for byte."""
    files = sorted(
        p.relative_to(folder)
        for p in folder.rglob("*")
        if p.is_file() and "__pycache__" not in p.parts
    )
    copied = sorted(p.relative_to(copy) for p in copy.rglob("*") if p.is_file())
    return files == copied and all(
        (copy / name).read_bytes() == (folder / name).read_bytes() for name in files
    )


@pytest.fixture
def world() -> Iterator[Path]:
    """The data and shared folders, and a wheel folder and certificates of the worker's own
    (its image's /wheels), in a folder the sandbox's uid can traverse (pytest's is root's)."""
    root = Path(tempfile.mkdtemp(prefix="arena-shared-test-"))
    root.chmod(0o755)
    for folder in ("data/inputs", "data/output", "wheels", "certs", "shared/stub", "shared/proxy"):
        (root / folder).mkdir(parents=True)
    (root / "wheels" / "onnxruntime-1.32.0-py3-none-any.whl").write_bytes(b"wheel" * 1000)
    (root / "wheels" / "sub").mkdir()
    (root / "wheels" / "sub" / "index.html").write_text("<a href='../x.whl'>x</a>")
    (root / "certs" / "ca.pem").write_text("-----BEGIN CERTIFICATE-----\n")
    yield root
    shutil.rmtree(root)


def resolver_spec(world: Path, shared: Path | None) -> LaunchSpec:
    """A resolver's launch as evaluator/resolver.py makes it: its stub and proxy socket in the
    shared folder, its request and output in the data folder, the worker's own folders."""
    data = world / "data"
    config = env_only(sandbox={"sandbox_shared_dir": shared}).sandbox
    mounts = (
        (str(world / "wheels"), world / "wheels"),
        (str(world / "certs"), world / "certs"),
        ("/run/arena-index", world / "shared" / "proxy"),
    )
    return LaunchSpec(
        submission=world / "shared" / "stub",
        deps=None,
        config=config,
        data_dir=data,
        training=Training(data / "inputs", data / "output", 10.0, 1024, mounts=mounts),
    )


def test_folders_the_daemon_cannot_see_are_bound_as_copies_in_the_shared_folder(world: Path):
    shared = world / "shared"
    seen = binds(container_options(resolver_spec(world, shared), None))
    for name in ("wheels", "certs"):
        target = str(world / name)  # at its own path inside: file: URLs read the same
        copy, mode = seen[target]
        assert (copy.parent, mode) == (shared / COPIES_DIR, "ro")
        assert copy.name.startswith(f"{name}-")
        assert same_files(copy, world / name)
    runtime_copy, _ = seen[RUNTIME_MOUNT]
    assert runtime_copy.parent == shared / COPIES_DIR and same_files(runtime_copy, runtime_dir())
    # What the daemon already sees is bound as it is: the proxy's live socket folder, the stub
    # in the shared folder, the request and the output in the data folder.
    assert seen["/run/arena-index"] == (shared / "proxy", "ro")
    assert seen["/submission"] == (shared / "stub", "ro")
    assert seen["/dataset"] == (world / "data" / "inputs", "ro")
    assert seen["/model"] == (world / "data" / "output", "rw")
    # One copy per content: a second launch binds the same ones and adds no folder.
    before = sorted((shared / COPIES_DIR).iterdir())
    assert binds(container_options(resolver_spec(world, shared), None)) == seen
    assert sorted((shared / COPIES_DIR).iterdir()) == before


@pytest.mark.skipif(os.geteuid() != 0, reason="reads as uid 65534, which needs root")
def test_the_sandbox_uid_reads_the_copies(world: Path):
    shared = world / "shared"
    seen = binds(container_options(resolver_spec(world, shared), None))
    wheel = seen[str(world / "wheels")][0] / "onnxruntime-1.32.0-py3-none-any.whl"
    index = seen[str(world / "wheels")][0] / "sub" / "index.html"
    for path in (wheel, index, seen[RUNTIME_MOUNT][0] / RUNTIME_MAIN):
        read = subprocess.run(
            ["cat", str(path)], user=UNPRIVILEGED_ID, group=UNPRIVILEGED_ID, capture_output=True
        )
        assert read.returncode == 0, read.stderr
        assert read.stdout == path.read_bytes()


def test_a_changed_folder_gets_a_new_copy_even_with_its_size_and_mtime_kept(world: Path):
    """The copy is remembered per process by its files' stat, not re-read per launch: a file
    rewritten in place under the same size and mtime still changes its ctime."""
    folder, shared = world / "wheels", world / "shared"
    wheel = folder / "pkg-1.0-py3-none-any.whl"
    wheel.write_bytes(b"first")
    first = shared_copy(folder, shared, "wheels")
    assert shared_copy(folder, shared, "wheels") == first
    status = wheel.stat()
    wheel.write_bytes(b"again")
    os.utime(wheel, ns=(status.st_atime_ns, status.st_mtime_ns))
    second = shared_copy(folder, shared, "wheels")
    assert second != first
    assert (second / wheel.name).read_bytes() == b"again"
    assert (first / wheel.name).read_bytes() == b"first"
    shutil.rmtree(second)  # a copy removed (the shared folder cleaned) is made again
    assert shared_copy(folder, shared, "wheels") == second and second.is_dir()


def test_copies_no_launch_used_for_a_day_are_removed(world: Path):
    """A new image's wheel folder leaves its old copy behind: the cleanup removes copies unused
    for a day, and a copy used again (its folder unchanged) is kept, or made again if gone."""
    shared = world / "shared"
    old = shared_copy(world / "wheels", shared, "wheels")
    kept = shared_copy(world / "certs", shared, "certs")
    half_made = shared / COPIES_DIR / ".wheels-unfinished"
    half_made.mkdir()
    long_ago = time.time() - STALE_COPY_AGE_S - 60
    for path in (old, kept, half_made):
        os.utime(path, (long_ago, long_ago))
    assert shared_copy(world / "certs", shared, "certs") == kept  # used now: touched
    assert remove_stale_copies(shared) == 2
    assert sorted((shared / COPIES_DIR).iterdir()) == [kept]
    assert shared_copy(world / "wheels", shared, "wheels") == old and same_files(
        old, world / "wheels"
    )
    # A folder whose content changed gets a new copy, which clears the copies unused for a day.
    os.utime(old, (long_ago, long_ago))
    (world / "certs" / "ca.pem").write_text("-----BEGIN CERTIFICATE-----\nnew\n")
    renewed = shared_copy(world / "certs", shared, "certs")
    assert sorted((shared / COPIES_DIR).iterdir()) == sorted([kept, renewed])


def test_without_a_shared_folder_every_folder_is_bound_as_it_is(world: Path):
    seen = binds(container_options(resolver_spec(world, None), None))
    assert seen[RUNTIME_MOUNT] == (runtime_dir(), "ro")
    assert seen[str(world / "wheels")] == (world / "wheels", "ro")
    assert seen[str(world / "certs")] == (world / "certs", "ro")
    assert socket_dir_for("abc", None).parent == Path(tempfile.gettempdir())


def test_the_sockets_go_to_the_shared_folder(world: Path):
    assert socket_dir_for("abc", world / "shared").parent == world / "shared"
