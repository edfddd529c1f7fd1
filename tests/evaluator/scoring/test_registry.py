import numpy as np
import pytest

from evaluator.scoring import ProfileError, ScoringProfile, load_profile
from evaluator.scoring.profile import profile_names
from evaluator.scoring.registry import UnknownTermError, get_term, register_term, term_names


def test_the_spec_terms_are_registered():
    assert set(term_names()) >= {"distance_obs", "jerk", "lc_off", "speeding", "wrong_way"}


def test_registering_a_name_twice_is_refused():
    with pytest.raises(ValueError, match="already registered"):
        register_term("jerk")(lambda track, profile: np.zeros(0))


def test_unknown_term_is_refused():
    with pytest.raises(UnknownTermError, match="nope"):
        get_term("nope")


def profile_fields(**changes) -> dict:
    return load_profile().model_dump() | changes


def test_default_profile_holds_the_spec_constants():
    profile = load_profile()
    assert profile.name == "driving-smarts-2022" and profile.version >= 1
    assert (profile.obs_headway_s, profile.obs_half_angle_deg, profile.obs_decay_per_m) == (
        3.0,
        40.0,
        0.05,
    )
    assert profile.speeding_tolerance_fraction == 0.5
    assert profile.wrong_way_angle_deg == 90.0
    assert (profile.max_episode_steps, profile.dt_s) == (800, 0.1)
    assert profile.humanness_terms == ("distance_obs", "jerk", "lc_off")
    assert profile.rules_terms == ("speeding", "wrong_way")


@pytest.mark.parametrize("name", profile_names())
def test_every_shipped_profile_loads_and_is_frozen(name):
    profile = load_profile(name)
    with pytest.raises(ValueError):
        profile.obs_headway_s = 1.0


@pytest.mark.parametrize(
    ("changes", "message"),
    [
        ({"humanness_terms": ["jerk", "nope"]}, "unknown metric term"),
        ({"rules_terms": ["speeding", "speeding"]}, "listed twice"),
        ({"obs_headway_sec": 3.0}, "Extra inputs"),
        ({"obs_decay_per_m": -1.0}, "greater than 0"),
    ],
)
def test_profile_with_a_bad_field_is_refused(changes, message):
    with pytest.raises(ValueError, match=message):
        ScoringProfile.model_validate(profile_fields(**changes))


def test_unknown_profile_name_lists_the_known_ones():
    with pytest.raises(ProfileError, match="driving-smarts-2022"):
        load_profile("nope")
