"""`arena replay --format html`: one file holding the replay viewer, its styles and the episode, so
it opens offline from a disk or a mail attachment."""

from __future__ import annotations

import json
from html import escape
from pathlib import Path

from evaluator.viewer.model import Replay

WEB_DIR = Path(__file__).resolve().parent / "web"
VIEWER_SCRIPT = WEB_DIR / "replay.js"
VIEWER_STYLES = WEB_DIR / "replay.css"

_PAGE = """<!doctype html>
<html lang="en">
<head>
<meta charset="utf-8">
<meta name="viewport" content="width=device-width, initial-scale=1">
<title>Replay {title} · Driving Arena</title>
<style>
body {{ margin: 0 auto; max-width: 1100px; padding: 1rem;
  font: 15px/1.5 system-ui, -apple-system, "Segoe UI", sans-serif; color: #1d2330; }}
h1 {{ font-size: 1.3rem; margin: .2rem 0 .8rem; overflow-wrap: anywhere; }}
button {{ padding: .4rem 1rem; font: inherit; color: #fff; background: #2457c5; border: 0;
  border-radius: 6px; cursor: pointer; }}
{styles}
</style>
</head>
<body>
<h1>Replay of {title}</h1>
<div id="replay"></div>
<script>{script}</script>
<script>ArenaReplay.mount(document.getElementById("replay"), {{ data: {data} }});</script>
</body>
</html>
"""


def _inline_json(replay: Replay) -> str:
    """JSON that cannot end the script element it sits in."""
    return json.dumps(replay.to_json(), separators=(",", ":")).replace("</", "<\\/")


def replay_html(replay: Replay) -> str:
    return _PAGE.format(
        title=escape(replay.scenario_id),
        styles=VIEWER_STYLES.read_text(),
        script=VIEWER_SCRIPT.read_text(),
        data=_inline_json(replay),
    )
