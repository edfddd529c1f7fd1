"""Names of the episode record's arrays (``docs/records.md``): the writer in ``sim`` and the reader
in ``evaluator.scoring`` both take them from here."""

from __future__ import annotations

FORMAT_VERSION = 1
RECORD_SUFFIX = ".npz"

EVENT_FLAGS = (
    "ev_collision",
    "ev_off_road",
    "ev_off_route",
    "ev_on_shoulder",
    "ev_wrong_way",
    "ev_not_moving",
    "ev_reached_goal",
)
# Per agent-step float arrays; scoring reads these same names (a valid row has them finite).
STEP_FLOATS = (
    "x",
    "y",
    "heading",
    "speed",
    "vx",
    "vy",
    "lane_offset",
    "lane_width",
    "lane_heading",
    "speed_limit",
)
# Per agent-step, per neighbour slot float arrays, stored as ``nbr_<name>``.
NEIGHBOUR_FLOATS = ("x", "y", "heading", "speed", "length", "width")
