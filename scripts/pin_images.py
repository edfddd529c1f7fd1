"""The images docker-compose.yml pulls, pinned by digest: prints the lines of an env file.

    python3 scripts/pin_images.py > images.env                   # after `docker pull` of each
    python3 scripts/pin_images.py --offline compose-test > images.env   # the offline stand-ins

A pulled image is pinned by its registry digest (``postgres@sha256:...``, from the local image's
``RepoDigests``: what `docker pull` recorded), so that a tag moved upstream never changes what
runs. The offline stand-ins (scripts/build_offline_images.py) never came from a registry and have
no registry digest: they are pinned by their image ID, the digest of their content
(``sha256:...``). Nothing is pulled here and no digest is made up: an image missing locally, or
pulled without a digest, is an error naming it.
"""

from __future__ import annotations

import argparse
import sys

import docker
import docker.errors

# The setting each pulled image is read from in docker-compose.yml, and the reference to pull.
PULLED = {
    "ARENA_PYTHON_IMAGE": "python:3.11-slim",
    "ARENA_POSTGRES_IMAGE": "postgres:16",
    "ARENA_REDIS_IMAGE": "redis:7",
}
# What stands in for each offline (scripts/build_offline_images.py: image_names).
OFFLINE = {
    "ARENA_PYTHON_IMAGE": "driving-arena-service-base:{tag}",
    "ARENA_POSTGRES_IMAGE": "driving-arena-postgres:{tag}",
    "ARENA_REDIS_IMAGE": "driving-arena-redis:{tag}",
}


def pinned(client: docker.DockerClient, reference: str, offline: bool) -> str:
    try:
        image = client.images.get(reference)
    except docker.errors.ImageNotFound:
        hint = "scripts/build_offline_images.py" if offline else f"docker pull {reference}"
        raise SystemExit(f"{reference} is not on this host: {hint} first") from None
    if offline:
        return image.id
    repository = reference.rsplit(":", 1)[0]
    digests = [d for d in image.attrs.get("RepoDigests") or [] if d.split("@")[0] == repository]
    if not digests:
        raise SystemExit(f"{reference} has no registry digest here: pull it from its registry")
    return digests[0]


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--offline", metavar="TAG", help="pin the offline stand-ins of TAG")
    args = parser.parse_args()
    client = docker.from_env()
    for setting, reference in PULLED.items():
        if args.offline:
            reference = OFFLINE[setting].format(tag=args.offline)
        print(f"{setting}={pinned(client, reference, args.offline is not None)}")


if __name__ == "__main__":
    sys.exit(main())
