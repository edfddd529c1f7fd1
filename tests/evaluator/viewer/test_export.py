"""`arena replay --format gif|mp4|html` on a real episode record: what is written is a valid
animation of the episode, and the HTML file animates in Chromium with nothing fetched."""

import json

import cv2
import numpy as np
import pytest

from arena_command import app
from tests.cli_runner import CliRunner
from tests.server.api.test_browser import CHROMIUM, CHROMIUM_ARGS


def replay(record, suite, *args):
    result = CliRunner().invoke(app, ["replay", str(record), "--suite", str(suite), *args])
    assert result.exit_code == 0, result.output
    return result


@pytest.mark.slow
def test_gif_has_one_frame_per_drawn_step_ends_on_the_last_and_the_vehicles_move(episode, tmp_path):
    from PIL import Image

    from evaluator.viewer.frames import HOLD_LAST_MS, frames
    from evaluator.viewer.model import load_replay

    suite, record = episode
    out = tmp_path / "e.gif"
    replay(record, suite, "--format", "gif", "--every", "3", "--out", str(out))
    assert out.read_bytes()[:6] == b"GIF89a"
    gif = Image.open(out)
    assert gif.n_frames == 21  # 60 steps, every 3rd (0..57), and the last one (59)
    durations = []
    pictures = []
    for k in range(gif.n_frames):
        gif.seek(k)
        durations.append(gif.info["duration"])
        pictures.append(np.asarray(gif.convert("RGB")).astype(int))
    assert durations == [300] * 20 + [HOLD_LAST_MS]  # [ms]: 3 steps of 0.1 s; the end held
    assert np.abs(pictures[0] - pictures[-1]).sum() > 0
    # What is stored is the drawing, to a palette's rounding: the terminal step included.
    drawn = list(frames(load_replay(record, suite), 3))
    last = cv2.cvtColor(drawn[-1], cv2.COLOR_BGR2RGB).astype(int)
    assert np.abs(pictures[-1] - last).mean() < 3


def test_a_gif_is_small(episode, tmp_path):
    """6 s of episode at 10 frames per second, 640 px wide: OpenCV's writer took 3.5 MB."""
    suite, record = episode
    out = tmp_path / "e.gif"
    replay(record, suite, "--format", "gif", "--out", str(out))
    assert out.stat().st_size < 400_000


def test_a_goal_out_of_view_is_pointed_at():
    from evaluator.viewer.frames import FramePainter

    painter = FramePainter.__new__(FramePainter)
    painter.width, painter.road_height, painter.scale = 640, 400, 640 / 110.0
    image = np.zeros((400, 640, 3), np.uint8)
    painter._goal_pointer(image, np.array([0.0, 0.0]), np.array([500.0, 0.0]))
    assert image[:, 560:].any() and not image[:, :300].any()  # at the right edge, towards it
    nothing = np.zeros_like(image)
    painter._goal_pointer(nothing, np.array([0.0, 0.0]), np.array([10.0, 0.0]))
    assert not nothing.any()  # in view: the goal circle says it


@pytest.mark.slow
def test_mp4_has_every_step(episode, tmp_path):
    suite, record = episode
    out = tmp_path / "e.mp4"
    replay(record, suite, "--format", "mp4", "--out", str(out))
    video = cv2.VideoCapture(str(out))
    assert video.isOpened() and int(video.get(cv2.CAP_PROP_FRAME_COUNT)) == 60
    assert video.get(cv2.CAP_PROP_FPS) == pytest.approx(10.0)
    video.release()


def test_results_folder_needs_a_known_scenario(tmp_path):
    (tmp_path / "results" / "records").mkdir(parents=True)
    result = CliRunner().invoke(app, ["replay", str(tmp_path / "results"), "nope"])
    assert result.exit_code == 2 and "no record for nope" in result.output


@pytest.mark.browser
@pytest.mark.skipif(not CHROMIUM.exists(), reason="needs Debian's chromium")
def test_html_file_plays_offline_in_chromium(episode, tmp_path):
    from playwright.sync_api import expect, sync_playwright

    suite, record = episode
    out = tmp_path / "e.html"
    replay(record, suite, "--format", "html", "--out", str(out))
    with sync_playwright() as playwright:
        browser = playwright.chromium.launch(executable_path=str(CHROMIUM), args=CHROMIUM_ARGS)
        page = browser.new_page(viewport={"width": 1000, "height": 800})
        fetched = []
        page.route("**/*", lambda route: (fetched.append(route.request.url), route.continue_()))
        page.goto(out.as_uri())
        expect(page.locator("#replay")).to_have_attribute("data-frame", "0")
        drawn = "() => document.getElementById('replay').replay.drawn"
        before = {v["id"]: v for v in page.evaluate(drawn)}
        page.click(".replay-play")
        expect(page.locator("#replay")).not_to_have_attribute("data-frame", "0")
        page.click(".replay-play")  # pause
        after = {v["id"]: v for v in page.evaluate(drawn)}
        assert after["Agent_1"]["x"] > before["Agent_1"]["x"]
        assert fetched == [out.as_uri()]  # the file itself, nothing else
        assert json.loads(page.evaluate("JSON.stringify(document.title)")).startswith("Replay")
        browser.close()


def test_labels_at_one_spot_are_stacked_apart():
    from evaluator.viewer.frames import place_labels

    sizes = [(60, 10), (60, 10), (80, 10), (40, 10)]
    anchors = [(100.0, 100.0, 4.0), (100.0, 102.0, 4.0), (95.0, 100.0, 12.0), (300.0, 50.0, 4.0)]
    car = (90.0, 70.0, 110.0, 90.0)  # a vehicle right above the first two anchors
    origins = place_labels(anchors, sizes, [car])
    boxes = [(x, y - h, x + w, y) for (x, y), (w, h) in zip(origins, sizes, strict=True)]
    for i, a in enumerate(boxes):
        for b in [*boxes[i + 1 :], car]:
            assert a[2] <= b[0] or b[2] <= a[0] or a[3] <= b[1] or b[3] <= a[1], (a, b)
    assert boxes[3][3] < 50  # alone: right above its anchor


@pytest.fixture(scope="module")
def broken_junctions(episode, tmp_path_factory):
    """The episode with its map's two junctions given invalid outlines (a bow tie, two lobes
    touching), as real CommonRoad intersections give them."""
    import shutil

    from tests.sim.builders import INVALID_JUNCTION_SHAPES, with_junction_shape

    suite, record = episode
    copy = tmp_path_factory.mktemp("broken") / "suite"
    shutil.copytree(suite, copy)
    net = next(copy.glob("*/*.net.xml"))
    with_junction_shape(net, "w", INVALID_JUNCTION_SHAPES["bow_tie"])
    with_junction_shape(net, "e", INVALID_JUNCTION_SHAPES["two_lobes_touching"])
    return copy, record


@pytest.mark.parametrize("fmt", ["svg", "html", "gif", "mp4"])
def test_every_format_draws_a_map_with_invalid_junction_outlines(broken_junctions, fmt, tmp_path):
    suite, record = broken_junctions
    out = tmp_path / f"e.{fmt}"
    replay(record, suite, "--format", fmt, "--out", str(out))
    assert out.stat().st_size > 1000
    if fmt == "html":  # the junctions are in the page's map
        assert '"junctions": [[' in out.read_text() or '"junctions":[[' in out.read_text()


def test_scenarios_show_draws_a_map_with_invalid_junction_outlines(broken_junctions, tmp_path):
    suite, _ = broken_junctions
    out = tmp_path / "s.svg"
    result = CliRunner().invoke(
        app, ["scenarios", "show", str(next(suite.iterdir())), "--out", str(out)]
    )
    assert result.exit_code == 0, result.output
    assert out.read_text().count("<polygon") > 2
