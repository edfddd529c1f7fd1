"""The sandbox's images, built offline: the agent runtime and the resolver's builder.

Production builds ``Dockerfile.agent`` from a registry. Where no registry is reachable (CI,
air-gapped hosts) :func:`build_image` makes the same runtime from Debian packages: debootstrap a
minimal bookworm root with ``python3`` and ``python3-numpy``, trim what an agent never needs, and
``docker import`` the tarball. The tarball is cached under the data dir, so a rebuild after the
image was removed takes seconds.

The builder image (:data:`BUILDER`) is made the same way with a C/C++ toolchain and Python's
headers: the resolver's ``build`` mode turns sdists into wheels in it, so no compiler is ever in
the image that runs policies. Both come from the same suite, hence the same ``python3`` minor
version: a wheel built in one is installable in the other.
"""

from __future__ import annotations

import shutil
import subprocess
import tempfile
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path

from arena.child_env import HOST_TOOL_VARIABLES, PACKAGE_INDEX_VARIABLES, child_environment
from arena.config import SandboxSettings
from arena.errors import SandboxUnavailable
from arena.files import replaced_atomically

DEBIAN_SUITE = "bookworm"
APT_SOURCES = (Path("/etc/apt/sources.list"), Path("/etc/apt/sources.list.d"))


@dataclass(frozen=True)
class ImageRecipe:
    """One offline image: ``role`` names its cached root, ``packages`` what debootstrap adds,
    ``setting`` the sandbox setting that names the image."""

    role: str
    packages: tuple[str, ...]
    setting: str

    def name(self, config: SandboxSettings) -> str:
        return getattr(config, self.setting)


AGENT = ImageRecipe("agent", ("python3", "python3-numpy"), "agent_image")
# What ``setup.py build_ext`` needs for C and C++ extensions; no network tool, no numpy (an
# sdist's build requirements are downloaded wheels).
BUILDER = ImageRecipe(
    "builder", ("python3", "python3-dev", "gcc", "g++", "make", "libc6-dev"), "builder_image"
)
RECIPES = {recipe.role: recipe for recipe in (AGENT, BUILDER)}
# Documentation, locales, package caches: nothing an agent needs, a third of the root's size.
TRIMMED = (
    "usr/share/doc",
    "usr/share/man",
    "usr/share/info",
    "usr/share/locale",
    "usr/share/lintian",
    "var/cache/apt",
    "var/cache/debconf",
    "var/lib/apt/lists",
    "var/log",
)
IMAGE_CHANGES = (
    "ENV PATH=/usr/local/bin:/usr/bin:/bin",
    "ENV PYTHONDONTWRITEBYTECODE=1",
    "WORKDIR /",
    'CMD ["python3"]',
)


def rootfs_cache(data_dir: Path, recipe: ImageRecipe = AGENT) -> Path:
    return data_dir / "sandbox" / f"{recipe.role}-rootfs-{DEBIAN_SUITE}.tar"


def debian_mirror(config: SandboxSettings, apt_sources: tuple[Path, ...] = APT_SOURCES) -> str:
    """The mirror to bootstrap from: the ``debian_mirror`` setting, else the Debian mirror the
    host's apt is configured with (one-line or deb822 sources), so debootstrap goes where apt is
    allowed to. No host name is built in: without either, a clear error."""
    if config.debian_mirror:
        return config.debian_mirror.rstrip("/")
    files = []
    for source in apt_sources:
        files += sorted(source.glob("*")) if source.is_dir() else [source]
    for source in files:
        if not source.is_file():
            continue
        for line in source.read_text(errors="replace").splitlines():
            words = line.split("#", 1)[0].split()
            urls = [w for w in words if w.startswith(("http://", "https://"))]
            if urls and "/debian" in urls[0] and "security" not in urls[0]:
                return urls[0].rstrip("/")
    raise SandboxUnavailable(
        "no Debian mirror to build the sandbox images from: set ARENA_DEBIAN_MIRROR, or configure "
        f"a Debian mirror in apt's sources ({', '.join(str(p) for p in apt_sources)})"
    )


def image_exists(client, image: str) -> bool:
    # deferred: the docker client is needed only with the Docker sandbox
    import docker.errors

    try:
        client.images.get(image)
    except docker.errors.ImageNotFound:
        return False
    return True


def build_rootfs_tarball(
    target: Path,
    mirror: str,
    log: Callable[[str], None],
    packages: tuple[str, ...] = AGENT.packages,
) -> None:
    """debootstrap a minimal root with ``packages`` (the agent's: python3 + numpy) and write it
    as an uncompressed tar."""
    if shutil.which("debootstrap") is None:
        raise SandboxUnavailable("debootstrap is not installed (apt-get install debootstrap)")
    target.parent.mkdir(parents=True, exist_ok=True)
    with tempfile.TemporaryDirectory(prefix="arena-rootfs-", dir=target.parent) as tmp:
        root = Path(tmp) / "root"
        log(f"debootstrap {DEBIAN_SUITE} from {mirror} (a few minutes)")
        command = [
            "debootstrap",
            "--variant=minbase",
            f"--include={','.join(packages)}",
            DEBIAN_SUITE,
            str(root),
            mirror,
        ]
        env = child_environment(inherit=[*HOST_TOOL_VARIABLES, *PACKAGE_INDEX_VARIABLES])
        done = subprocess.run(command, capture_output=True, text=True, env=env)
        if done.returncode != 0:
            raise SandboxUnavailable(f"debootstrap failed:\n{done.stdout[-4000:]}{done.stderr}")
        # debootstrap can leave /proc (and /sys) of the chroot mounted; a tar of a live /proc
        # fails, and the temporary folder could not be removed.
        _unmount_below(root)
        for relative in TRIMMED:
            shutil.rmtree(root / relative, ignore_errors=True)
            (root / relative).mkdir(parents=True, exist_ok=True)
        with replaced_atomically(target) as partial:
            subprocess.run(
                ["tar", "--one-file-system", "-C", str(root), "-cf", str(partial), "."],
                check=True,
                env=child_environment(),
            )
    log(f"cached root at {target}")


def _unmount_below(root: Path) -> None:
    """Unmount every mount point inside ``root``, deepest first."""
    prefix = str(root.resolve()) + "/"
    mounts = [
        line.split()[1]
        for line in Path("/proc/self/mounts").read_text().splitlines()
        if line.split()[1].startswith(prefix)
    ]
    for mount in sorted(mounts, key=len, reverse=True):
        subprocess.run(["umount", "--lazy", mount], check=False, env=child_environment())


def build_image(
    config: SandboxSettings,
    data_dir: Path,
    *,
    force: bool = False,
    log: Callable[[str], None] = print,
    recipe: ImageRecipe = AGENT,
) -> str:
    """Make ``recipe``'s image (``config.agent_image`` or ``config.builder_image``) exist in the
    local Docker daemon, its Debian root file system cached under ``data_dir``; returns its
    id."""
    # deferred: the docker client is needed only with the Docker sandbox
    import docker
    import docker.errors

    try:
        client = docker.from_env()
        client.ping()
    except docker.errors.DockerException as error:
        raise SandboxUnavailable(f"no Docker daemon answers: {error}") from error
    image = recipe.name(config)
    if not force and image_exists(client, image):
        log(f"{image} already present")
        return client.images.get(image).id
    tarball = rootfs_cache(data_dir, recipe)
    if force or not tarball.is_file():
        build_rootfs_tarball(tarball, debian_mirror(config), log, recipe.packages)
    repository, _, tag = image.rpartition(":") if ":" in image else (image, "", "latest")
    log(f"docker import {tarball.name} as {image}")
    client.api.import_image_from_file(
        str(tarball), repository=repository, tag=tag or "latest", changes=list(IMAGE_CHANGES)
    )
    return client.images.get(image).id
