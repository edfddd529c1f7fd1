"""Which scenarios run several episodes, and the traffic seed of each."""

from arena.episodes import Episode, episode_count, episodes_of, traffic_seed
from arena.suite import ManifestEntry

REACTIVE = ManifestEntry(id="p010_merge_2lane_low", family="merge")
REPLAY = ManifestEntry(id="p050_replay_cut_off", family="replay", reactive=False)


def test_episode_zero_is_the_scenario_seed():
    assert traffic_seed(REACTIVE.id, 1234, 0) == 1234


def test_later_seeds_are_deterministic_distinct_and_fit_sumo():
    seeds = [traffic_seed(REACTIVE.id, 1234, k) for k in range(50)]
    assert seeds == [traffic_seed(REACTIVE.id, 1234, k) for k in range(50)]
    assert len(set(seeds)) == 50
    assert all(0 <= seed < 2**31 for seed in seeds)


def test_seeds_depend_on_the_scenario():
    assert traffic_seed("a", 1, 1) != traffic_seed("b", 1, 1)
    assert traffic_seed("a", 1, 1) != traffic_seed("a", 2, 1)


def test_only_reactive_scenarios_repeat():
    assert (episode_count(REACTIVE, 3), episode_count(REPLAY, 3)) == (3, 1)
    assert episodes_of([REACTIVE, REPLAY], 2) == (
        Episode(REACTIVE.id, 0),
        Episode(REACTIVE.id, 1),
        Episode(REPLAY.id, 0),
    )


def test_episode_names_keep_the_first_one_as_before():
    assert Episode("s1").name == "s1"
    assert Episode("s1", 2).name == "s1.ep2"
