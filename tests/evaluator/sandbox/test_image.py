"""Where the offline agent image is bootstrapped from: a setting or the host's apt sources only."""

from __future__ import annotations

from pathlib import Path

import pytest

from arena.config import Settings
from arena.errors import SandboxUnavailable
from evaluator.sandbox import image
from tests.settings import with_fields

ONE_LINE = "deb http://mirror.example.test/debian bookworm main\n"
DEB822 = (
    "Types: deb\n"
    "URIs: http://security.example.test/debian-security\n"
    "Suites: bookworm-security\n\n"
    "Types: deb\n"
    "# a comment naming http://elsewhere.example.test/debian\n"
    "URIs: http://deb822.example.test/debian/\n"
    "Suites: bookworm\n"
)


def sources(tmp_path: Path, **files: str) -> tuple[Path, ...]:
    folder = tmp_path / "sources.list.d"
    folder.mkdir()
    for name, text in files.items():
        (folder / name).write_text(text)
    return (tmp_path / "sources.list", folder)


def test_the_mirror_comes_from_apt_sources_one_line_or_deb822(tmp_path):
    settings = with_fields(Settings(), storage={"data_dir": tmp_path})
    assert image.debian_mirror(settings.sandbox, sources(tmp_path, a="", b=DEB822)) == (
        "http://deb822.example.test/debian"
    )
    (tmp_path / "sources.list").write_text(ONE_LINE)
    only_list = (tmp_path / "sources.list",)
    assert image.debian_mirror(settings.sandbox, only_list) == "http://mirror.example.test/debian"


def test_the_setting_wins_and_nothing_is_built_in(tmp_path):
    configured = with_fields(
        Settings(),
        storage={"data_dir": tmp_path},
        sandbox={"debian_mirror": "http://local.example.test/debian/"},
    )
    assert image.debian_mirror(configured.sandbox, ()) == "http://local.example.test/debian"
    with pytest.raises(SandboxUnavailable, match="ARENA_DEBIAN_MIRROR"):
        image.debian_mirror(
            with_fields(Settings(), storage={"data_dir": tmp_path}).sandbox,
            sources(tmp_path, a="# nothing\n"),
        )
