"""A real service stack for end-to-end tests (:mod:`server.processes`): a small suite of public
scenarios, a database, a broker, an API process and Celery worker processes."""

from __future__ import annotations

from pathlib import Path

from server.processes import (
    EXAMPLES,
    FINISHED,
    SCENARIOS,
    build_small_suite,
    cut_suite,
    shared_dir,
    start_worker,
    upload_folder,
    wait_finished,
)


def upload_example(url: str, token: str, name: str, zips: Path) -> int:
    return upload_folder(url, token, EXAMPLES / name, zips)


__all__ = [
    "EXAMPLES",
    "FINISHED",
    "SCENARIOS",
    "build_small_suite",
    "cut_suite",
    "shared_dir",
    "start_worker",
    "upload_folder",
    "wait_finished",
]
