"""The variants of each reactive family: a checked table, so a misspelt variant fails the build
naming the known ones instead of silently building another scenario.

Each row says everything the generator needs that differs between variants of a family.
"""

from __future__ import annotations

from dataclasses import dataclass

from arena.errors import ArenaError
from arena.scenario import Family


@dataclass(frozen=True)
class Variant:
    template: str  # the map template (scenarios/maps.py) the variant is built on
    slow_leaders: bool = False  # overtake: leaders at 5-7 m/s instead of 9-12 m/s
    turn: str | None = None  # intersections: "l" or "r" from the southern arm
    goal_lane: int | None = None  # intersections: the exit lane; None draws one


class UnknownVariant(ArenaError, ValueError):
    """A suite composition names a variant its family does not have."""


# Replays: one variant per recorded kind, cut from a scene recorded on one map.
KIND_SCENE = {
    "cruise": "highway",
    "lane_change": "highway",
    "merge": "highway",
    "overtake": "highway",
    "cut_off": "highway",
    "i80_bubble": "highway",
    "right_turn": "cross",
    "left_turn": "cross",
    "urban": "urban",
}
# Naturalistic replays (scenarios/recorded/naturalistic.py): the manoeuvre of the removed vehicle.
NATURALISTIC_KINDS = tuple(
    f"ngsim_{kind}" for kind in ("cruise", "lane_change", "left_turn", "right_turn")
)


def _turn_c(template: str, turn: str, goal_lane: int) -> Variant:
    return Variant(template, turn=turn, goal_lane=goal_lane)


VARIANTS: dict[Family, dict[str, Variant]] = {
    Family.cruise: {
        "2lane": Variant("highway_2lane"),
        "3lane_curve": Variant("highway_3lane_curve"),
        "4lane": Variant("highway_4lane"),
    },
    Family.overtake: {
        "2lane": Variant("highway_2lane"),
        "2lane_slow": Variant("highway_2lane", slow_leaders=True),
        "3lane_curve": Variant("highway_3lane_curve"),
        "3lane_curve_slow": Variant("highway_3lane_curve", slow_leaders=True),
        "4lane": Variant("highway_4lane"),
        "4lane_slow": Variant("highway_4lane", slow_leaders=True),
    },
    Family.cut_in: {
        "3lane": Variant("highway_3lane"),
        "4lane": Variant("highway_4lane"),
    },
    Family.merge: {
        name: Variant(f"merge_{name}")
        for name in (
            "2lane",
            "2lane_shoulder",
            "2lane_shoulder_short",
            "3lane_curve",
            "3lane_shoulder",
            "3lane_shoulder_short",
            "4lane",
        )
    },
    Family.left_turn_t: {
        "left_turn_t": Variant("t_intersection", turn="l"),
        "left_turn_t_rotated": Variant("t_intersection_rotated", turn="l"),
    },
    Family.turn_c: {
        "left_turn_c": _turn_c("cross", "l", 2),
        "left_turn_c_rotated": _turn_c("cross_rotated", "l", 2),
        "left_turn_middle_lane_c": _turn_c("cross", "l", 1),
        "left_turn_upside_c": _turn_c("cross_upside", "l", 2),
        "left_turn_upside_c_rotated": _turn_c("cross_upside_rotated", "l", 2),
        "right_turn_c": _turn_c("cross", "r", 0),
        "right_turn_c_rotated": _turn_c("cross_rotated", "r", 0),
    },
}


def known_variants(family: Family) -> tuple[str, ...]:
    if family is Family.replay:
        return tuple(KIND_SCENE) + NATURALISTIC_KINDS
    return tuple(VARIANTS[family])


def check_variant(family: Family, variant: str) -> None:
    known = known_variants(family)
    if variant not in known:
        raise UnknownVariant(
            f"unknown {family.value} variant {variant!r} (known: {', '.join(known)})"
        )


def variant_of(family: Family, variant: str) -> Variant:
    check_variant(family, variant)
    return VARIANTS[family][variant]
