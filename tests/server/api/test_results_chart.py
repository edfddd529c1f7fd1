"""The submission's results drawn on the server (GET /submissions/{id}/results.svg): the four
metrics per family beside the leaderboard's median, and completion's interval as a bar."""

from __future__ import annotations

import xml.etree.ElementTree as ET

from server.charts import Figure, family_medians, results_chart
from tests.server.builders import bearer, make_team, queued_submission, seed_scored

SVG = "{http://www.w3.org/2000/svg}"


def families(completion: float, time: float) -> dict:
    return {
        "cruise": {"scenarios": 4, "completion": completion, "time": time, "humanness": 0.5,
                   "rules": None},
        "merge": {"scenarios": 4, "completion": 1.0, "time": 800.0, "humanness": 0.25,
                  "rules": 0.0},
    }  # fmt: skip


def titles(svg: str) -> list[str]:
    return [element.text for element in ET.fromstring(svg).iter(f"{SVG}title")]


def test_the_results_are_drawn_beside_the_leaderboards_median(client, db):
    team, token = make_team(db, "alpha")
    mine = seed_scored(
        db, team, (0.5, 500.0, 0.5, 0.0), interval=(0.40625, 0.65625), families=families(0.5, 500)
    )
    for name, completion in (("beta", 0.25), ("gamma", 0.0)):
        other, _ = make_team(db, name)
        seed_scored(db, other, (completion, 400.0, 0.5, 0.0), families=families(completion, 300))
    response = client.get(f"/api/v1/submissions/{mine}/results.svg", headers=bearer(token))
    assert response.status_code == 200
    assert response.headers["content-type"].startswith("image/svg+xml")
    said = titles(response.text)
    # The interval, written as everywhere else (a half rounded away from zero).
    assert any("95% interval [0.4063, 0.6563]" in title for title in said)
    # Cruise: this submission 0.5, the board's three entries 0.5, 0.25 and 0: median 0.25.
    assert "completion: 0.5000" in said and "leaderboard median: 0.2500" in said
    assert "leaderboard median: 300.0" in said  # time: 500, 300, 300
    root = ET.fromstring(response.text)
    bars = [e for e in root.iter(f"{SVG}rect") if e.get("class") == "bar"]
    assert len(bars) == 2 * 4 - 1  # cruise's rules were not measured: no bar


def test_nothing_is_drawn_before_a_score_nor_for_another_team(client, db):
    team, token = make_team(db, "alpha")
    queued = queued_submission(db, team)
    refused = client.get(f"/api/v1/submissions/{queued}/results.svg", headers=bearer(token))
    assert refused.status_code == 409 and "nothing to draw yet" in refused.json()["detail"]
    other, _ = make_team(db, "beta")
    theirs = seed_scored(db, other, (0.5, 500.0, 0.5, 0.0), families=families(0.5, 500))
    response = client.get(f"/api/v1/submissions/{theirs}/results.svg", headers=bearer(token))
    assert response.status_code == 404


def test_a_chart_escapes_its_text_and_medians_skip_what_was_not_measured():
    medians = family_medians(
        [{"a<b>": {"completion": 1.0, "time": 1.0, "humanness": None, "rules": 2.0}},
         {"a<b>": {"completion": 0.0, "time": 3.0, "humanness": None, "rules": 4.0}}]
    )  # fmt: skip
    assert medians == {"a<b>": {"completion": 0.5, "time": 2.0, "humanness": None, "rules": 3.0}}
    figure = Figure(values=medians["a<b>"], median=medians["a<b>"])
    svg = results_chart(0.5, None, {"a<b>": figure})
    assert "a&lt;b&gt;" in svg and "a<b>" not in svg
    ET.fromstring(svg)  # well-formed
