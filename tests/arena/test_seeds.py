"""The hidden suite's secret seed may be a passphrase: the same text always gives the same
integer, different texts different ones; a number stays itself."""

from __future__ import annotations

import pytest

from arena.config import Settings
from arena.seeds import SeedError, parse_seed


def test_a_number_is_itself_and_a_passphrase_a_stable_large_integer():
    assert parse_seed("20221128") == 20221128
    assert parse_seed(7) == 7
    secret = parse_seed("correct horse battery staple")
    assert secret == parse_seed("correct horse battery staple")
    assert secret != parse_seed("correct horse battery stapler")
    assert secret > 2**32  # the whole 64 bits, not a guessable small number


@pytest.mark.parametrize("bad", ["", "   ", -1])
def test_an_empty_or_negative_seed_is_refused(bad):
    with pytest.raises(SeedError):
        parse_seed(bad)


def test_the_setting_takes_a_passphrase_too(monkeypatch):
    monkeypatch.setenv("ARENA_HIDDEN_SEED", "s3cret phrase")
    assert Settings().suites.hidden_seed == parse_seed("s3cret phrase")
    monkeypatch.setenv("ARENA_HIDDEN_SEED", "")
    assert Settings().suites.hidden_seed is None
