"""The reproducibility manifest: built from what the episodes ran with, compared component by
component, and shown to a team without scenario ids or seeds."""

from pathlib import Path

from arena.suite import ManifestEntry, Suite, SuiteManifest
from evaluator.provenance import Environment, EpisodeRun, Manifest, differences, manifest_of

ENV = Environment(arena="0.1.0", python="3.11.7", numpy="2.4.6", sumo="1.28.0", sandbox="docker")
SUITE = Suite(
    root=Path("unit"),
    manifest=SuiteManifest(
        suite="hidden",
        scenarios=(
            ManifestEntry(id="hidden_cruise_0", family="cruise", hash="c" * 64),
            ManifestEntry(id="hidden_merge_0", family="merge", hash="d" * 64, reactive=False),
        ),
    ),
    sha256="e" * 64,
)


def manifest(env=ENV, seeds=(11, 12), **pins):
    runs = [
        EpisodeRun("hidden_cruise_0", 0, seeds[0], env),
        EpisodeRun("hidden_cruise_0", 1, seeds[1], env),
        EpisodeRun("hidden_merge_0", 0, 7, env),
    ]
    values = {
        "submission": "a" * 64,
        "model": None,
        "episodes_per_scenario": 2,
        "profile": "driving-smarts-2022",
        "profile_version": "1",
    } | pins
    return manifest_of(SUITE, reversed(runs), **values)


def test_seeds_follow_the_episodes_and_environments_are_listed_once():
    m = manifest()
    assert m.scenarios["hidden_cruise_0"].seeds == (11, 12)
    assert m.scenarios["hidden_merge_0"].seeds == (7,)
    assert m.environments == (ENV,)
    assert differences(m, manifest()) == []


def test_every_differing_component_is_named():
    m = manifest()
    changed = manifest(
        env=ENV.model_copy(update={"sumo": "1.27.0"}),
        seeds=(11, 13),
        submission="b" * 64,
        model="f" * 64,
        profile_version="2",
    )
    named = [text.split(" ")[0].rstrip(":") for text in differences(m, changed)]
    assert named == ["submission", "model", "scenarios", "profile_version", "environment.sumo"]


def test_the_public_view_names_no_scenario_and_no_seed():
    public = manifest().public()
    text = public.model_dump_json()
    assert "hidden_" not in text and '"11"' not in text and "12," not in text
    assert public.scenario_hashes == ("c" * 64, "d" * 64)
    # The seeds are pinned by digest: other seeds, another digest.
    assert public.seeds_sha256 != manifest(seeds=(11, 13)).public().seeds_sha256


def test_the_agents_stack_is_recorded_but_a_rerun_is_not_refused_over_it():
    ran = ENV.model_copy(update={"agent_stack": {"python": "3.11.2", "numpy": "1.23.5"}})
    m = manifest(env=ran)
    assert m.environments[0].agent_stack["numpy"] == "1.23.5"
    assert Manifest.model_validate_json(m.model_dump_json()) == m
    # An audit knows the agent's stack only once it has run the agent again.
    assert differences(m, manifest()) == []


def test_a_reported_stack_keeps_a_few_short_strings_only():
    """The stack is the sandbox's word: what is not a short string pair is dropped, and a
    report of thousands of entries keeps 32."""
    from evaluator.sandbox.handle import MAX_STACK_ENTRIES, reported_stack

    assert reported_stack(["numpy"]) == {}
    kept = reported_stack({"numpy": "1.23.5", "torch": 2, "x" * 65: "1", "scipy": "y" * 65})
    assert kept == {"numpy": "1.23.5"}
    many = reported_stack({f"m{i:05d}": "1" for i in range(5000)})
    assert len(many) == MAX_STACK_ENTRIES
