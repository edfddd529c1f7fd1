"""Where requirements resolve from when the service names no index: the host's pip
configuration, read through `pip config list` (real pip, a configuration file of the test's)."""

from __future__ import annotations

from collections.abc import Iterator
from pathlib import Path

import pytest

from submissions.intake.package_index import host_pip_sources


@pytest.fixture
def pip_config(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> Iterator[Path]:
    """A pip configuration file of the test's alone (the host's are not read), and the sources
    read afresh."""
    path = tmp_path / "pip.conf"
    monkeypatch.setenv("PIP_CONFIG_FILE", str(path))
    for name in ("PIP_INDEX_URL", "PIP_EXTRA_INDEX_URL", "PIP_NO_INDEX", "PIP_FIND_LINKS"):
        monkeypatch.delenv(name, raising=False)
    host_pip_sources.cache_clear()
    yield path
    host_pip_sources.cache_clear()


def test_a_pip_without_an_index_gives_its_wheel_folders_only(pip_config: Path) -> None:
    """The offline service image's pip (no-index, find-links=/wheels): no default index put in
    its place, which the resolver would try before the folder and never reach."""
    pip_config.write_text("[global]\nno-index = true\nfind-links = /wheels\n")
    sources = host_pip_sources()
    assert sources.index_urls == ()
    assert sources.find_links == ("/wheels",)
    assert sources.file_hosts == ()


def test_a_pip_with_an_index_keeps_it_and_its_wheel_folders(pip_config: Path) -> None:
    pip_config.write_text(
        "[global]\nindex-url = http://127.0.0.1:3141/simple\nfind-links = /wheels\n"
    )
    sources = host_pip_sources()
    assert sources.index_urls == ("http://127.0.0.1:3141/simple",)
    assert sources.find_links == ("/wheels",)
