from __future__ import annotations

import numpy as np
import pytest

from arena.scenario import Family
from scenarios.generators import GENERATORS, MapLibrary, Spec
from scenarios.maps import TEMPLATES
from scenarios.suites import REACTIVE
from scenarios.variants import VARIANTS, UnknownVariant, variant_of

ONE_PER_FAMILY = {family: (variants[0], volumes[0]) for family, variants, volumes, _ in REACTIVE}


def _draft(family, variant, volume, seed, cache_dir, agents=1):
    return GENERATORS[family](
        Spec(family, variant, volume, agents), np.random.default_rng(seed), MapLibrary(cache_dir)
    )


@pytest.mark.parametrize("family", sorted(GENERATORS, key=str))
def test_generator_is_deterministic_in_its_seed(family, cache_dir):
    variant, volume = ONE_PER_FAMILY[family]
    a = _draft(family, variant, volume, 3, cache_dir)
    b = _draft(family, variant, volume, 3, cache_dir)
    c = _draft(family, variant, volume, 4, cache_dir)
    assert a.routes.to_xml() == b.routes.to_xml() and a.missions == b.missions
    assert a.routes.to_xml() != c.routes.to_xml()


def _flow_rate(draft) -> float:
    return sum(f.per_hour for f in draft.routes.flows)


@pytest.mark.parametrize(
    ("family", "variant", "low", "high"),
    [(Family.cruise, "2lane", "low", "high"), (Family.merge, "2lane", "low", "mid")],
)
def test_volume_raises_flow_rates(family, variant, low, high, cache_dir):
    rates = [_flow_rate(_draft(family, variant, v, 11, cache_dir)) for v in (low, high)]
    assert rates[1] > 1.4 * rates[0]


def test_drivers_are_heterogeneous(cache_dir):
    draft = _draft(Family.cruise, "4lane", "high", 5, cache_dir)
    models = {vt["carFollowModel"] for vt in draft.routes.vtypes}
    assert len(draft.routes.vtypes) >= 4
    assert len({vt["tau"] for vt in draft.routes.vtypes}) == len(draft.routes.vtypes)
    assert models <= {"IDM", "Krauss"}


def test_cut_in_has_a_trigger_on_the_agent(cache_dir):
    draft = _draft(Family.cut_in, "3lane", "mid", 2, cache_dir)
    (trigger,) = draft.triggers
    assert trigger.agent_id == "Agent_0"
    assert trigger.vehicle in {v.id for v in draft.routes.vehicles}


def test_overtake_slow_variant_has_slower_leaders(cache_dir):
    def leader_speed(variant):
        draft = _draft(Family.overtake, variant, "low", 9, cache_dir)
        (slow,) = [t for t in draft.routes.special_types if t["id"] == "slow"]
        return float(slow["maxSpeed"])

    assert leader_speed("2lane_slow") < leader_speed("2lane")


@pytest.mark.parametrize(("variant", "agents"), [("2lane", 2), ("3lane_curve", 3)])
def test_multi_agent_cruise_has_delayed_starts(variant, agents, cache_dir):
    draft = _draft(Family.cruise, variant, "low", 1, cache_dir, agents=agents)
    assert [m.agent_id for m in draft.missions] == [f"Agent_{i}" for i in range(agents)]
    assert draft.missions[0].start_step == 0
    assert all(m.start_step > 0 for m in draft.missions[1:])


def test_an_unknown_variant_fails_naming_the_known_ones():
    with pytest.raises(UnknownVariant, match=r"unknown cruise variant '3lane_curvy'.*3lane_curve"):
        Spec(Family.cruise, "3lane_curvy", "low")
    with pytest.raises(UnknownVariant, match=r"known: .*lane_change"):
        Spec(Family.replay, "lane_chnage", None, reactive=False)


@pytest.mark.parametrize(
    ("family", "variant"), [(f, v) for f, rows in VARIANTS.items() for v in rows]
)
def test_every_variant_names_a_map_template_that_exists(family, variant):
    assert variant_of(family, variant).template in TEMPLATES
