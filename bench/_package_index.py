"""A package index on loopback for bench/stacks.py's smoke mode and the requirement tests: wheels
and sdists the caller builds itself, served as a PEP 503 simple index by a thread of its own
process (nothing leaves the machine). A shared helper, not a benchmark."""

from __future__ import annotations

import hashlib
import io
import tarfile
import threading
import zipfile
from collections.abc import Iterator
from contextlib import contextmanager
from functools import partial
from http.server import SimpleHTTPRequestHandler, ThreadingHTTPServer
from pathlib import Path

from packaging.utils import canonicalize_name


def build_wheel(
    folder: Path,
    name: str,
    version: str = "1.0",
    files: dict[str, bytes] | None = None,
    *,
    requires: tuple[str, ...] = (),
    tag: str = "py3-none-any",
) -> Path:
    """A minimal wheel (``files`` default: ``<name>/__init__.py`` holding its version)."""
    module = name.replace("-", "_")
    files = files if files is not None else {f"{module}/__init__.py": f"V = {version!r}\n".encode()}
    dist = f"{module}-{version}.dist-info"
    metadata = f"Metadata-Version: 2.1\nName: {name}\nVersion: {version}\n"
    metadata += "".join(f"Requires-Dist: {r}\n" for r in requires)
    path = folder / f"{module}-{version}-{tag}.whl"
    with zipfile.ZipFile(path, "w", zipfile.ZIP_DEFLATED) as archive:
        for file_name, data in files.items():
            archive.writestr(file_name, data)
        archive.writestr(f"{dist}/METADATA", metadata)
        archive.writestr(
            f"{dist}/WHEEL", f"Wheel-Version: 1.0\nRoot-Is-Purelib: true\nTag: {tag}\n"
        )
        archive.writestr(f"{dist}/RECORD", "")
    return path


def build_sdist(folder: Path, name: str, version: str, files: dict[str, str]) -> Path:
    """An sdist holding ``files`` (paths inside ``<name>-<version>/``) and its PKG-INFO."""
    base = f"{name}-{version}"
    path = folder / f"{base}.tar.gz"
    files = {**files, "PKG-INFO": f"Metadata-Version: 2.1\nName: {name}\nVersion: {version}\n"}
    with tarfile.open(path, "w:gz") as archive:
        for member_name, text in files.items():
            data = text.encode()
            info = tarfile.TarInfo(f"{base}/{member_name}")
            info.size = len(data)
            archive.addfile(info, io.BytesIO(data))
    return path


def write_simple_index(files: Path, root: Path) -> None:
    """``root/simple/<project>/index.html`` for every distribution in ``files`` (linked with its
    sha256, as an index serves them)."""
    projects: dict[str, list[Path]] = {}
    for path in sorted(files.iterdir()):
        name = path.name.split("-")[0]
        projects.setdefault(canonicalize_name(name), []).append(path)
    for project, paths in projects.items():
        page = root / "simple" / project
        page.mkdir(parents=True, exist_ok=True)
        links = "".join(
            f'<a href="../../files/{p.name}#sha256={hashlib.sha256(p.read_bytes()).hexdigest()}">'
            f"{p.name}</a>\n"
            for p in paths
        )
        (page / "index.html").write_text(f"<!DOCTYPE html><html><body>\n{links}</body></html>\n")


@contextmanager
def served_index(files: Path, root: Path) -> Iterator[str]:
    """Serve ``files`` as a simple index on 127.0.0.1; yields its URL (``.../simple``)."""
    root.mkdir(parents=True, exist_ok=True)
    if (root / "files") != files:
        (root / "files").symlink_to(files, target_is_directory=True)
    write_simple_index(files, root)

    class Quiet(SimpleHTTPRequestHandler):
        def log_message(self, *_: object) -> None:
            pass

    server = ThreadingHTTPServer(("127.0.0.1", 0), partial(Quiet, directory=str(root)))
    # shutdown() waits for the loop's next poll: the default 0.5 s would end each use of it.
    thread = threading.Thread(target=server.serve_forever, args=(0.02,), daemon=True)
    thread.start()
    try:
        yield f"http://127.0.0.1:{server.server_address[1]}/simple"
    finally:
        server.shutdown()
        server.server_close()
