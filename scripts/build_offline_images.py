"""Build the images `docker-compose.yml` runs, offline: from Debian packages and local wheels.

Where no container registry is reachable (CI, air-gapped hosts) `python:3.11-slim`,
`postgres:16` and `redis:7` cannot be pulled. This builds stand-ins the way the agent runtime is
built (`arena sandbox build-image`): one debootstrapped Debian root from the mirror of the host's
apt sources (or ARENA_DEBIAN_MIRROR), `docker import`ed once, then

* ``driving-arena-service:<tag>``: the project's own ``Dockerfile`` built on that root
  (``--build-arg BASE_IMAGE``), its Python dependencies installed with ``--no-index`` from
  wheels that ``pip download`` fetched on the host with the host's pip configuration (and
  completed until the image's own pip resolves them);
* ``driving-arena-postgres:<tag>``: Debian's PostgreSQL behind an entrypoint that does what the
  official image's does with ``POSTGRES_USER`` / ``POSTGRES_PASSWORD`` / ``POSTGRES_DB``;
* ``driving-arena-redis:<tag>``: Debian's Redis, started like the official image starts it.

Every image is built only when missing (``--force`` rebuilds); the root tarball and the wheels
are cached under the data dir, so the CPU-heavy steps run once per machine. Builds run with no
network. Prints the image names, one ``role=image`` a line.

    python3 scripts/build_offline_images.py [--tag compose-test] [--force]
"""

from __future__ import annotations

import argparse
import contextlib
import hashlib
import re
import shutil
import subprocess
import sys
import tempfile
import tomllib
from pathlib import Path

import docker
import docker.errors

from arena.config import get_settings
from evaluator.sandbox.image import build_rootfs_tarball, debian_mirror

REPO = Path(__file__).resolve().parents[1]
# One root for all three images (one debootstrap: it is the slow, CPU-heavy step). The libraries
# are the ones the Dockerfile installs for libsumo and SUMO's binaries.
ROOT_PACKAGES = (
    "python3",
    "python3-pip",
    "python-is-python3",
    "passwd",  # useradd, for the Dockerfile's service user
    "ca-certificates",
    "libgl1",
    "libx11-6",
    "libxext6",
    "libxrender1",
    "libatomic1",
    "libexpat1",
    "zlib1g",
    # The Dockerfile's build stage compiles the simulator's core (setup.py) and cannot reach apt.
    "gcc",
    "libc6-dev",
    "python3-dev",
    "postgresql",
    "redis-server",
)
# As python:3.11-slim's: the sbin folders too (useradd).
ROOT_CHANGES = (
    "ENV PATH=/usr/local/sbin:/usr/local/bin:/usr/sbin:/usr/bin:/sbin:/bin",
    "WORKDIR /",
)
# What the submissions the deployment test uploads ask for in their requirements.txt: the
# service resolves them at intake, from the image's wheelhouse (it has no index either).
EXAMPLE_REQUIREMENTS = (REPO / "examples" / "ppo" / "requirements.txt",)

# The digest of what an image was built from: a changed input rebuilds it.
INPUTS_LABEL = "driving-arena.inputs"
SERVICE_BASE = """\
FROM {root}
COPY wheels /wheels
# The image's Python is its own (as python:3.11-slim's is), and pip installs from /wheels only.
RUN rm -f /usr/lib/python3*/EXTERNALLY-MANAGED \\
    && printf '[global]\\nno-index = true\\nfind-links = /wheels\\n' > /etc/pip.conf
"""

POSTGRES = """\
FROM {root}
RUN ln -s "$(ls -d /usr/lib/postgresql/*/bin | tail -n 1)" /usr/lib/postgresql/bin
ENV PATH=/usr/lib/postgresql/bin:/usr/local/bin:/usr/bin:/bin \\
    PGDATA=/var/lib/postgresql/data
COPY entrypoint.sh /usr/local/bin/docker-entrypoint.sh
RUN chmod 755 /usr/local/bin/docker-entrypoint.sh
VOLUME ["/var/lib/postgresql/data"]
EXPOSE 5432
STOPSIGNAL SIGINT
ENTRYPOINT ["docker-entrypoint.sh"]
CMD ["postgres"]
"""

# The official image's contract: on an empty data folder, initialise it with POSTGRES_USER (the
# superuser), POSTGRES_PASSWORD (or the file POSTGRES_PASSWORD_FILE names) and POSTGRES_DB,
# UTF-8 (a database in SQL_ASCII hands text to psycopg as bytes), password authentication from
# every host; then run the server as the postgres user.
POSTGRES_ENTRYPOINT = """\
#!/bin/sh
set -eu
mkdir -p "$PGDATA" /run/postgresql
chown -R postgres:postgres "$PGDATA" /run/postgresql
chmod 700 "$PGDATA"
as_postgres() { setpriv --reuid=postgres --regid=postgres --init-groups "$@"; }
user="${POSTGRES_USER:-postgres}"
if [ -n "${POSTGRES_PASSWORD_FILE:-}" ]; then
  POSTGRES_PASSWORD="$(cat "$POSTGRES_PASSWORD_FILE")"
fi
if [ ! -s "$PGDATA/PG_VERSION" ]; then
  : "${POSTGRES_PASSWORD:?the postgres stand-in needs POSTGRES_PASSWORD or POSTGRES_PASSWORD_FILE}"
  pwfile="$(mktemp)"
  printf '%s\\n' "$POSTGRES_PASSWORD" > "$pwfile"
  chown postgres "$pwfile"
  as_postgres initdb -D "$PGDATA" -U "$user" --pwfile="$pwfile" -E UTF8 --locale=C.UTF-8 \\
    --auth-local=trust --auth-host=scram-sha-256 >/dev/null
  rm -f "$pwfile"
  echo "host all all all scram-sha-256" >> "$PGDATA/pg_hba.conf"
  echo "listen_addresses = '*'" >> "$PGDATA/postgresql.conf"
  db="${POSTGRES_DB:-$user}"
  if [ "$db" != postgres ]; then
    as_postgres pg_ctl -D "$PGDATA" -o "-c listen_addresses=''" -w start >/dev/null
    as_postgres psql -v ON_ERROR_STOP=1 -U "$user" -d postgres -q -c "CREATE DATABASE \\"$db\\""
    as_postgres pg_ctl -D "$PGDATA" -m fast -w stop >/dev/null
  fi
fi
if [ "$1" = postgres ]; then
  shift
  exec setpriv --reuid=postgres --regid=postgres --init-groups postgres -D "$PGDATA" "$@"
fi
exec "$@"
"""

REDIS = """\
FROM {root}
COPY entrypoint.sh /usr/local/bin/docker-entrypoint.sh
RUN chmod 755 /usr/local/bin/docker-entrypoint.sh && mkdir -p /data && chown redis:redis /data
VOLUME ["/data"]
WORKDIR /data
EXPOSE 6379
ENTRYPOINT ["docker-entrypoint.sh"]
CMD ["redis-server"]
"""

# As the official image: without a configuration file Redis would refuse every client but
# loopback (protected mode); the server runs as the redis user in /data. A configuration read
# from standard input (`redis-server -`, docker-compose.yml's password) stays the last argument.
REDIS_ENTRYPOINT = """\
#!/bin/sh
set -eu
if [ "$1" = redis-server ]; then
  shift
  set -- redis-server --protected-mode no "$@"
  chown -R redis:redis /data
  exec setpriv --reuid=redis --regid=redis --init-groups "$@"
fi
exec "$@"
"""


def log(message: str) -> None:
    print(f"build-images: {message}", file=sys.stderr, flush=True)


def image_names(tag: str) -> dict[str, str]:
    return {
        "root": f"driving-arena-compose-root:{tag}",
        "service-base": f"driving-arena-service-base:{tag}",
        "service": f"driving-arena-service:{tag}",
        "postgres": f"driving-arena-postgres:{tag}",
        "redis": f"driving-arena-redis:{tag}",
    }


def cache_dir() -> Path:
    return get_settings().storage.resolved_data_dir / "compose-images"


def project_requirements() -> list[str]:
    """The project's dependencies and build requirements, and the examples' requirements."""
    pyproject = tomllib.loads((REPO / "pyproject.toml").read_text())
    wanted = [*pyproject["project"]["dependencies"], *pyproject["build-system"]["requires"]]
    wanted.append("wheel")  # older setuptools ask for it to build an editable install
    for listed in EXAMPLE_REQUIREMENTS:
        wanted += [line.strip() for line in listed.read_text().splitlines() if line.strip()]
    return wanted


def wheelhouse(client: docker.DockerClient, root: str, force: bool) -> Path:
    """Wheels of everything the image installs, fetched with the host's pip configuration
    (binary wheels only: nothing is built), then completed for the image's Python: environment
    markers can ask more of it than of the host's (``python_full_version < "3.11.3"``)."""
    folder = cache_dir() / "wheels"
    requirements = "\n".join(project_requirements()) + "\n"
    listed = folder / "requirements.txt"
    if not force and listed.is_file() and listed.read_text() == requirements:
        return folder
    shutil.rmtree(folder, ignore_errors=True)
    folder.mkdir(parents=True)
    log(f"pip download: {len(requirements.splitlines())} requirements into {folder}")
    (folder / "wanted.txt").write_text(requirements)
    download(folder, "-r", str(folder / "wanted.txt"))
    for _ in range(MAX_COMPLETIONS):
        missing = missing_in_image(client, root, folder)
        if missing is None:
            break
        log(f"the image's Python also needs {missing}")
        download(folder, "--no-deps", missing)
    else:
        raise SystemExit("the wheelhouse does not resolve in the image")
    listed.write_text(requirements)
    return folder


MAX_COMPLETIONS = 20
MISSING = re.compile(r"No matching distribution found for ([^;\s]+)")


def download(folder: Path, *what: str) -> None:
    command = [sys.executable, "-m", "pip", "download", "-q", "--only-binary=:all:"]
    subprocess.run([*command, "--dest", str(folder), *what], check=True)


def missing_in_image(client: docker.DockerClient, root: str, folder: Path) -> str | None:
    """The first requirement the image's pip cannot resolve from ``folder``, or None."""
    command = (
        "pip download -q --no-index --find-links /wheels -d /tmp/resolved -r /wheels/wanted.txt"
    )
    try:
        client.containers.run(
            root,
            ["sh", "-c", command],
            network_mode="none",
            volumes={str(folder): {"bind": "/wheels", "mode": "ro"}},
            remove=True,
            stderr=True,
        )
    except docker.errors.ContainerError as error:
        output = error.stderr.decode(errors="replace") if error.stderr else ""
        found = MISSING.search(output)
        if found is None:
            raise SystemExit(f"pip in the image failed:\n{output[-3000:]}") from error
        return found.group(1)
    return None


def label(client: docker.DockerClient, image: str, name: str) -> str | None:
    try:
        return (client.images.get(image).labels or {}).get(name)
    except docker.errors.ImageNotFound:
        return None


def exists(client: docker.DockerClient, image: str) -> bool:
    try:
        client.images.get(image)
    except docker.errors.ImageNotFound:
        return False
    return True


def import_root(client: docker.DockerClient, image: str, digest: str, force: bool) -> None:
    tarball = cache_dir() / f"root-bookworm-{digest_of(*ROOT_PACKAGES)[:12]}.tar"
    if force or not tarball.is_file():
        build_rootfs_tarball(
            tarball, debian_mirror(get_settings().sandbox), log, packages=ROOT_PACKAGES
        )
    repository, tag = image.split(":")
    log(f"docker import {tarball.name} as {image}")
    client.api.import_image_from_file(
        str(tarball),
        repository=repository,
        tag=tag,
        changes=[*ROOT_CHANGES, f"LABEL {INPUTS_LABEL}={digest}"],
    )


def build(
    client: docker.DockerClient,
    image: str,
    context: Path,
    dockerfile: str = "Dockerfile",
    buildargs: dict[str, str] | None = None,
) -> None:
    """``docker build`` with no network: everything comes from the context and the base."""
    log(f"docker build {image}")
    try:
        client.images.build(
            path=str(context),
            dockerfile=dockerfile,
            tag=image,
            buildargs=buildargs or {},
            network_mode="none",
            rm=True,
            forcerm=True,
        )
    except docker.errors.BuildError as error:
        output = "".join(
            str(chunk.get("stream", chunk.get("error", ""))) for chunk in error.build_log
        )
        raise SystemExit(f"docker build {image} failed:\n{output[-6000:]}") from error


def build_from_text(
    client: docker.DockerClient,
    image: str,
    dockerfile: str,
    files: dict[str, str | Path],
    digest: str,
) -> None:
    """Build ``image`` from a Dockerfile text and a context of ``files`` (text, or a folder),
    labelled with the digest of its inputs."""
    with tempfile.TemporaryDirectory(prefix="arena-image-", dir=cache_dir()) as tmp:
        context = Path(tmp)
        (context / "Dockerfile").write_text(f"{dockerfile}LABEL {INPUTS_LABEL}={digest}\n")
        for name, content in files.items():
            if isinstance(content, Path):
                # Hard links: the wheelhouse is large and on the same file system.
                shutil.copytree(content, context / name, copy_function=_link_or_copy)
            else:
                (context / name).write_text(content)
        build(client, image, context)


def _link_or_copy(source: str, target: str) -> None:
    try:
        Path(target).hardlink_to(source)
    except OSError:
        shutil.copy2(source, target)


def digest_of(*parts: str) -> str:
    return hashlib.sha256("\0".join(parts).encode()).hexdigest()


def build_images(tag: str, force: bool = False) -> dict[str, str]:
    """Each image is rebuilt when the digest of its inputs (packages, Dockerfile text, files,
    wheels, the image below) differs from its label, or with ``force``."""
    names = image_names(tag)
    client = docker.from_env(timeout=1800)
    cache_dir().mkdir(parents=True, exist_ok=True)

    def stale(role: str, digest: str) -> bool:
        return force or label(client, names[role], INPUTS_LABEL) != digest

    root = digest_of(*ROOT_PACKAGES, *ROOT_CHANGES)
    if stale("root", root):
        import_root(client, names["root"], root, force)
    wheels = wheelhouse(client, names["root"], force)
    for role, text, files in [
        ("service-base", SERVICE_BASE, {"wheels": wheels}),
        ("postgres", POSTGRES, {"entrypoint.sh": POSTGRES_ENTRYPOINT}),
        ("redis", REDIS, {"entrypoint.sh": REDIS_ENTRYPOINT}),
    ]:
        dockerfile = text.format(root=names["root"])
        contents = [
            (w / "requirements.txt").read_text() if isinstance(w, Path) else w
            for w in files.values()
        ]
        digest = digest_of(root, dockerfile, *contents)
        if stale(role, digest):
            build_from_text(client, names[role], dockerfile, files, digest)
    # The service image always: the project's code changes between runs (its dependencies are
    # a cached layer, so this takes seconds when only code changed).
    replaced = image_id(client, names["service"])
    build(client, names["service"], REPO, buildargs={"BASE_IMAGE": names["service-base"]})
    if replaced not in (None, image_id(client, names["service"])):
        # The previous build lost its tag: ours, and nothing else refers to it.
        with contextlib.suppress(docker.errors.APIError):
            client.images.remove(replaced)
    return names


def image_id(client: docker.DockerClient, image: str) -> str | None:
    try:
        return client.images.get(image).id
    except docker.errors.ImageNotFound:
        return None


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--tag", default="compose-test", help="tag of every image built")
    parser.add_argument("--force", action="store_true", help="rebuild everything")
    arguments = parser.parse_args()
    for role, image in build_images(arguments.tag, arguments.force).items():
        print(f"{role}={image}")


if __name__ == "__main__":
    main()
