"""Suite manifests: typed, strict, one place that knows where suites live."""

import json

import pytest

from arena.errors import SuiteError
from arena.suite import SHIPPED_PUBLIC_DIR, load_suite, public_suite_dir, resolve_suite
from tests.settings import env_only


def write_suite(folder, ids_families, suite="unit", **extra_entry):
    folder.mkdir(parents=True, exist_ok=True)
    scenarios = [
        {"id": i, "family": f, "variant": "v", "hash": "0", **extra_entry} for i, f in ids_families
    ]
    (folder / "manifest.json").write_text(json.dumps({"suite": suite, "scenarios": scenarios}))
    for scenario_id, _ in ids_families:
        (folder / scenario_id).mkdir(exist_ok=True)
    return folder


def test_selection_keeps_manifest_order_and_refuses_unknown_ids(tmp_path):
    suite = load_suite(write_suite(tmp_path, [("a", "cruise"), ("b", "merge")]))
    assert [s.id for s in suite.select(["b", "a"]).scenarios] == ["a", "b"]
    with pytest.raises(SuiteError, match="no scenario c"):
        suite.select(["c"])


def test_folder_without_manifest_is_a_clear_error(tmp_path):
    with pytest.raises(SuiteError, match=r"no manifest\.json"):
        load_suite(tmp_path)


def test_misspelt_manifest_key_is_refused(tmp_path):
    write_suite(tmp_path, [("a", "cruise")], famly="merge")
    with pytest.raises(SuiteError, match="famly"):
        load_suite(tmp_path)


def test_unknown_family_is_refused(tmp_path):
    write_suite(tmp_path, [("a", "crusie")])
    with pytest.raises(SuiteError, match="crusie"):
        load_suite(tmp_path)


def test_shipped_manifest_round_trips_byte_for_byte():
    raw = (SHIPPED_PUBLIC_DIR / "manifest.json").read_text()
    assert load_suite(SHIPPED_PUBLIC_DIR).manifest.to_json() == raw


def test_public_and_hidden_are_located_from_the_settings(tmp_path):
    suites = env_only().suites
    assert public_suite_dir(suites) == SHIPPED_PUBLIC_DIR
    assert resolve_suite("public", suites, tmp_path) == SHIPPED_PUBLIC_DIR
    assert resolve_suite("hidden", suites, tmp_path) == tmp_path / "suites" / "hidden"
    configured = env_only(suites={"public_suite_dir": tmp_path / "p"}).suites
    assert resolve_suite("public", configured, tmp_path) == tmp_path / "p"
    assert resolve_suite(tmp_path / "x", suites, tmp_path) == tmp_path / "x"
