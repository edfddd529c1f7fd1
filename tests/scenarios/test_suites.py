from __future__ import annotations

import json
from collections import Counter

import pytest

from arena.scenario import Family, content_hash, load_scenario
from scenarios.suites import (
    REACTIVE,
    REPLAYS,
    build_suite,
    derive_seed,
    public_specs,
    seed_fingerprint,
)
from tests.scenarios.conftest import manifest

REACTIVE_ROWS = [
    (family, variant, volume, agents)
    for family, variants, volumes, agent_counts in REACTIVE
    for variant in variants
    for volume in volumes
    for agents in agent_counts
]


def test_hidden_suite_has_128_scenarios_71_reactive(hidden_dev):
    entries = manifest(hidden_dev)["scenarios"]
    assert len(entries) == 128
    assert sum(e["reactive"] for e in entries) == 71
    assert sum(not e["reactive"] for e in entries) == 57
    assert len({e["id"] for e in entries}) == 128


@pytest.mark.parametrize(("family", "variant", "volume", "agents"), REACTIVE_ROWS)
def test_hidden_suite_has_each_reactive_row_once(hidden_dev, family, variant, volume, agents):
    rows = Counter(
        (e["family"], e["variant"], e["volume"], e["agents"])
        for e in manifest(hidden_dev)["scenarios"]
        if e["reactive"]
    )
    assert rows[(family.value, variant, volume, agents)] == 1


@pytest.mark.parametrize(("kind", "agents", "count"), REPLAYS)
def test_hidden_suite_replay_counts(hidden_dev, kind, agents, count):
    entries = manifest(hidden_dev)["scenarios"]
    found = [
        e for e in entries if not e["reactive"] and e["variant"] == kind and e["agents"] == agents
    ]
    assert len(found) == count
    assert all(e["family"] == "replay" and e["label"] == "recorded" for e in found)


def test_bubble_replay_is_the_one_reactive_replay(hidden_dev):
    bubble = [
        e for e in manifest(hidden_dev)["scenarios"] if e["family"] == "replay" and e["reactive"]
    ]
    assert len(bubble) == 1
    scenario = load_scenario(hidden_dev / bubble[0]["id"])
    assert scenario.traffic.kind == "replay" and scenario.traffic.bubble_radius > 0


def test_manifest_hashes_match_folders_and_hide_the_seed(hidden_dev):
    data = manifest(hidden_dev)
    assert "seed" not in data
    from arena.config import get_settings

    assert data["seed_fingerprint"] == seed_fingerprint(get_settings().suites.development_seed)
    text = (hidden_dev / "manifest.json").read_text()
    assert str(get_settings().suites.development_seed) not in text
    for e in data["scenarios"][::9]:
        assert content_hash(hidden_dev / e["id"]) == e["hash"]


@pytest.mark.slow
def test_same_seed_same_bytes_other_seed_other_hashes(hidden_dev, tmp_path, cache_dir):
    from arena.config import get_settings

    again = build_suite(
        "hidden", get_settings().suites.development_seed, tmp_path / "again", cache_dir
    )
    assert [e.hash for e in again.scenarios] == [
        e["hash"] for e in manifest(hidden_dev)["scenarios"]
    ]
    other = build_suite("hidden", 1, tmp_path / "other", cache_dir)
    ours = {e["hash"] for e in manifest(hidden_dev)["scenarios"]}
    assert not ours & {e.hash for e in other.scenarios}


def _traffic_bytes(folder):
    scenario = load_scenario(folder)
    name = (
        scenario.traffic.routes
        if scenario.traffic.kind == "sumo"
        else scenario.traffic.trajectories
    )
    return (folder / name).read_bytes(), json.dumps(
        [m.model_dump(mode="json") for m in scenario.missions]
    )


@pytest.mark.slow
def test_no_public_scenario_equals_a_hidden_one(hidden_dev, public_fresh):
    hidden = manifest(hidden_dev)["scenarios"]
    public = manifest(public_fresh)["scenarios"]
    assert not {e["hash"] for e in hidden} & {e["hash"] for e in public}
    hidden_content = {_traffic_bytes(hidden_dev / e["id"]) for e in hidden}
    for e in public:
        assert _traffic_bytes(public_fresh / e["id"]) not in hidden_content, e["id"]


def test_seeds_are_domain_separated():
    assert derive_seed("public", 5, 0) != derive_seed("hidden", 5, 0)
    assert derive_seed("hidden", 5, 0) == derive_seed("hidden", 5, 0)


def test_public_set_covers_every_family_and_variant(public_fresh):
    entries = manifest(public_fresh)["scenarios"]
    assert {e["family"] for e in entries} == {f.value for f in Family}
    variants = {(e["family"], e["variant"]) for e in entries}
    for family, variant_names, _, _ in REACTIVE:
        for variant in variant_names:
            assert (family.value, variant) in variants
    assert {kind for kind, _, _ in REPLAYS} <= {e["variant"] for e in entries if not e["reactive"]}
    assert len(entries) == len(public_specs())


def test_shipped_public_set_is_the_committed_seed_build(public_fresh):
    from arena.suite import SHIPPED_PUBLIC_DIR
    from scenarios.maps import netconvert_version

    shipped = manifest(SHIPPED_PUBLIC_DIR)
    # SUMO is pinned in pyproject.toml: another netconvert means a broken install or a pin bumped
    # without rebuilding the shipped set (`arena scenarios build --suite public`).
    assert shipped.get("netconvert") == netconvert_version(), "rebuild the public set"
    fresh = manifest(public_fresh)
    assert [e["hash"] for e in shipped["scenarios"]] == [e["hash"] for e in fresh["scenarios"]]
