"""`arena replay --format gif|mp4`: the replay drawn frame by frame with OpenCV, the camera
following the first mission agent, and its speed and events on a strip under the road, like the
replay page. The video always ends on the episode's last step (its terminal event), held a
moment; a goal out of view is pointed at from the edge with its distance.

GIFs are written with Pillow: one palette of ``GIF_COLOURS`` colours shared by every frame and
only the changed rectangle of each frame stored (OpenCV's writer: 6 MB for 20 s, this: about
30 times less for the same pictures).
"""

from __future__ import annotations

import math
from collections.abc import Iterable, Iterator
from pathlib import Path

import cv2
import numpy as np
from PIL import Image

from evaluator.viewer.model import STYLE, Replay, ReplayError

GIF_COLOURS = 64  # the drawings use a dozen colours and their anti-aliased edges
HOLD_LAST_MS = 2000  # the terminal frame stays this long before the GIF loops

FRAME_WIDTH_PX = 640
ROAD_HEIGHT_PX = 400
STRIP_HEIGHT_PX = 90  # the speed and event timeline under the road
VIEW_WIDTH_M = 110.0  # road shown around the followed vehicle
FONT = cv2.FONT_HERSHEY_SIMPLEX


def _bgr(colour: str) -> tuple[int, int, int]:
    r, g, b = (int(colour[i : i + 2], 16) for i in (1, 3, 5))
    return (b, g, r)


class FramePainter:
    """Draws frame ``f`` of a replay as an (H, W, 3) BGR image."""

    def __init__(self, replay: Replay, width: int = FRAME_WIDTH_PX) -> None:
        self.replay = replay
        self.width = width
        self.road_height = round(width * ROAD_HEIGHT_PX / FRAME_WIDTH_PX)
        self.height = self.road_height + STRIP_HEIGHT_PX
        self.scale = width / VIEW_WIDTH_M  # [px/m]
        self.ego = replay.agents[0]
        self._centres = self._camera_path()

    def _camera_path(self) -> np.ndarray:
        """(F, 2) centre of view [m]: the followed vehicle, holding its nearest known pose before
        it starts and after it ends."""
        v = self.ego.vehicle
        xy = np.column_stack([self.replay.x[v], self.replay.y[v]])
        known = np.flatnonzero(np.isfinite(xy[:, 0]))
        nearest = known[np.clip(np.searchsorted(known, np.arange(len(xy)), "right") - 1, 0, None)]
        return xy[nearest]

    def _px(self, xy: np.ndarray, centre: np.ndarray) -> np.ndarray:
        xy = np.asarray(xy, dtype=float).reshape(-1, 2)
        px = (xy - centre) * [self.scale, -self.scale] + [self.width / 2, self.road_height / 2]
        return np.round(px * 16).astype(np.int32)  # 4 fractional bits (cv2 `shift`)

    def frame(self, f: int) -> np.ndarray:
        image = np.empty((self.height, self.width, 3), np.uint8)
        image[:] = _bgr(STYLE["background"])
        centre = self._centres[f]
        self._road(image, centre)
        self._goals(image, centre)
        self._vehicles(image, centre, f)
        self._strip(image, f)
        return image

    def _road(self, image: np.ndarray, centre: np.ndarray) -> None:
        road = self.replay.road
        if road is None:
            return
        for shapes, colour in (
            (road.junctions, "junction"),
            (road.lanes, "road"),
            (road.shoulders, "shoulder"),
        ):
            polygons = [self._px(shape, centre) for shape in shapes]
            cv2.fillPoly(image, polygons, _bgr(STYLE[colour]), cv2.LINE_AA, shift=4)
        for lines, colour in ((road.dashed, "#b8bcc2"), (road.solid, STYLE["marking"])):
            polylines = [self._px(line, centre) for line in lines]
            cv2.polylines(image, polylines, False, _bgr(colour), 1, cv2.LINE_AA, shift=4)
        for line in road.stop_lines:
            cv2.polylines(image, [self._px(line, centre)], False, (255, 255, 255), 2, shift=4)

    def _goals(self, image: np.ndarray, centre: np.ndarray) -> None:
        for agent in self.replay.agents:
            gx, gy, radius = agent.goal
            ((cx, cy),) = self._px([gx, gy], centre)
            r = round(max(radius * self.scale, 4) * 16)
            cv2.circle(image, (int(cx), int(cy)), r, _bgr(STYLE["goal"]), 2, cv2.LINE_AA, shift=4)
        gx, gy, _ = self.ego.goal
        self._goal_pointer(image, centre, np.array([gx, gy]))

    def _goal_pointer(self, image: np.ndarray, centre: np.ndarray, goal: np.ndarray) -> None:
        """An arrow at the edge of the road view towards the followed agent's goal when it is
        out of view (the strip under the road says how far it is)."""
        offset = (goal - centre) * [self.scale, -self.scale]  # [px], y down
        half = np.array([self.width / 2, self.road_height / 2]) - 24
        if np.all(np.abs(offset) <= half):
            return  # the circle itself is in view
        tip = offset * min(half[0] / max(abs(offset[0]), 1e-9), half[1] / max(abs(offset[1]), 1e-9))
        mid = np.array([self.width / 2, self.road_height / 2])
        head = mid + tip
        tail = head - 30 * tip / np.linalg.norm(tip)
        colour = _bgr(STYLE["goal"])
        cv2.arrowedLine(
            image,
            tuple(np.round(tail).astype(int)),
            tuple(np.round(head).astype(int)),
            colour,
            3,
            cv2.LINE_AA,
            tipLength=0.4,
        )

    def _vehicles(self, image: np.ndarray, centre: np.ndarray, f: int) -> None:
        r = self.replay
        labels, boxes = [], []
        for v, kind in enumerate(r.kinds):
            x, y, heading = r.x[v, f], r.y[v, f], r.heading[v, f]
            if not np.isfinite(x):
                continue
            c, s = math.cos(heading), math.sin(heading)
            rot = np.array([[c, -s], [s, c]])
            box = np.array([[0.5, 0.5], [0.5, -0.5], [-0.5, -0.5], [-0.5, 0.5]])
            body = (box * [r.length[v], r.width[v]]) @ rot.T + [x, y]
            nose = (box * [0.2, 1.0] + [0.4, 0.0]) * [r.length[v], r.width[v]] @ rot.T + [x, y]
            cv2.fillPoly(image, [self._px(body, centre)], _bgr(STYLE[kind.value]), shift=4)
            cv2.polylines(image, [self._px(body, centre)], True, (34, 34, 34), 1, shift=4)
            cv2.fillPoly(image, [self._px(nose, centre)], (50, 50, 50), shift=4)
            anchor = self._px([x, y], centre)[0] // 16
            half = r.length[v] * self.scale / 2
            boxes.append((anchor[0] - half, anchor[1] - half, anchor[0] + half, anchor[1] + half))
            if kind.value != "traffic":
                labels.append((r.vehicle_ids[v], anchor, r.width[v] * self.scale))
        for agent in r.agents if len(r.agents) > 1 else ():
            gx, gy, radius = agent.goal
            ((px, py),) = self._px([gx, gy], centre) // 16
            labels.append((f"goal {agent.id}", (px, py), max(radius * self.scale, 4)))
        self._labels(image, labels, boxes)

    def _labels(self, image: np.ndarray, labels: list, boxes: list[Box]) -> None:
        """Fixed pixel size, drawn last so no vehicle hides one; each goes above or below its
        anchor, out of the way of those already placed."""
        sizes = [cv2.getTextSize(text, FONT, 0.45, 1)[0] for text, _, _ in labels]
        anchors = [(float(x), float(y), float(gap)) for _, (x, y), gap in labels]
        origins = place_labels(anchors, sizes, boxes, self.road_height)
        for (text, _, _), (x, y) in zip(labels, origins, strict=True):
            cv2.putText(image, text, (x, y), FONT, 0.45, (255, 255, 255), 3, cv2.LINE_AA)
            cv2.putText(image, text, (x, y), FONT, 0.45, (17, 17, 17), 1, cv2.LINE_AA)

    def _strip(self, image: np.ndarray, f: int) -> None:
        r, ego = self.replay, self.ego
        top = self.road_height
        image[top:] = 255
        left, right = 44, self.width - 10
        y0, y1 = self.height - 20, top + 22
        speeds = np.concatenate([ego.speed, ego.speed_limit])
        vmax = max(float(np.nanmax(speeds, initial=1.0)), 1.0) * 1.1
        fx = np.linspace(left, right, r.frames)

        def points(values: np.ndarray) -> list[np.ndarray]:
            ok = np.isfinite(values)
            xy = np.column_stack([fx, y0 - np.nan_to_num(values) / vmax * (y0 - y1)])
            return [np.round(xy[ok] * 16).astype(np.int32)] if ok.any() else []

        cv2.polylines(image, points(ego.speed_limit), False, (179, 162, 152), 1, shift=4)
        colour = _bgr(STYLE[r.kinds[ego.vehicle].value])
        cv2.polylines(image, points(ego.speed), False, colour, 2, cv2.LINE_AA, shift=4)
        for frame, name in ego.events:
            x = int(fx[frame])
            cv2.line(image, (x, y1 - 2), (x, y0), _bgr(STYLE["events"][name]), 1)
        x = int(fx[f])
        cv2.line(image, (x, y1 - 2), (x, y0), (48, 35, 29), 2)
        speed = ego.speed[f]
        shown = f"{speed:.1f} m/s" if np.isfinite(speed) else "-"
        step = r.first_step + f
        last = r.first_step + r.frames - 1
        gx, gy, _ = ego.goal
        to_goal = float(np.hypot(*(np.array([gx, gy]) - self._centres[f])))
        caption = f"step {step}/{last}  {step * r.dt:.1f} s  {ego.id} {shown}  goal {to_goal:.0f} m"
        cv2.putText(image, caption, (left, top + 14), FONT, 0.42, (48, 35, 29), 1, cv2.LINE_AA)
        seen = [name.replace("_", " ") for frame, name in ego.events if frame <= f]
        if seen:
            text = ", ".join(seen[-3:])
            (w, _), _ = cv2.getTextSize(text, FONT, 0.42, 1)
            org = (right - w, top + 14)
            cv2.putText(image, text, org, FONT, 0.42, _bgr("#b42318"), 1, cv2.LINE_AA)
        cv2.putText(image, f"{vmax:.0f}", (6, y1 + 4), FONT, 0.38, (133, 112, 102), 1)
        cv2.putText(image, "0", (6, y0), FONT, 0.38, (133, 112, 102), 1)


Box = tuple[float, float, float, float]  # x0, y0, x1, y1 [px]


def place_labels(
    anchors: list[tuple[float, float, float]],
    sizes: list[tuple[int, int]],
    obstacles: list[Box] = (),
    height: float = float("inf"),
) -> list[tuple[int, int]]:
    """Text origins [px] for labels of ``sizes`` (w, h) at ``anchors`` (x, y, gap): the first
    spot, alternately above and below the anchor by ``gap`` and more, inside rows 0..``height``,
    that overlaps no label placed before it and none of the ``obstacles`` (the vehicles drawn)."""
    placed: list[Box] = []
    origins = []
    for (x, y, gap), (w, h) in zip(anchors, sizes, strict=True):
        spots = []
        for k in range(12):
            lift = gap + 8 + (k // 2) * (h + 4)
            baseline = y - lift if k % 2 == 0 else y + lift + h
            spots.append((baseline, (x - w / 2 - 2, baseline - h - 1, x + w / 2 + 2, baseline + 3)))
        # Nowhere clear (a crowd of vehicles): right above the anchor.
        baseline, box = next(
            (
                (baseline, box)
                for baseline, box in spots
                if box[1] >= 0
                and box[3] <= height
                and all(
                    box[2] <= q[0] or q[2] <= box[0] or box[3] <= q[1] or q[3] <= box[1]
                    for q in [*placed, *obstacles]
                )
            ),
            spots[0],
        )
        placed.append(box)
        origins.append((round(x - w / 2), round(baseline)))
    return origins


def frame_indices(replay: Replay, every: int = 1) -> list[int]:
    """Every ``every``-th frame, and always the last: the video ends on the terminal step."""
    indices = list(range(0, replay.frames, every))
    if indices[-1] != replay.frames - 1:
        indices.append(replay.frames - 1)
    return indices


def frames(replay: Replay, every: int = 1, width: int = FRAME_WIDTH_PX) -> Iterator[np.ndarray]:
    painter = FramePainter(replay, width)
    for f in frame_indices(replay, every):
        yield painter.frame(f)


def frame_count(replay: Replay, every: int = 1) -> int:
    return len(frame_indices(replay, every))


def write_gif(images: Iterable[np.ndarray], out: Path, frame_ms: int) -> Path:
    """An animated GIF that loops, one image per ``frame_ms`` milliseconds, the last one held
    :data:`HOLD_LAST_MS`. One palette for all frames (taken from frames across the episode), no
    dithering: flat colours stay flat, and each frame stores only what changed."""
    drawn = [cv2.cvtColor(image, cv2.COLOR_BGR2RGB) for image in images]
    picks = np.linspace(0, len(drawn) - 1, min(len(drawn), 8)).astype(int)
    sample = Image.fromarray(np.concatenate([drawn[i] for i in picks], axis=0))
    palette = sample.quantize(GIF_COLOURS, Image.Quantize.MEDIANCUT, dither=Image.Dither.NONE)
    frames_ = [
        Image.fromarray(image).quantize(palette=palette, dither=Image.Dither.NONE)
        for image in drawn
    ]
    durations = [frame_ms] * len(frames_)
    durations[-1] = max(frame_ms, HOLD_LAST_MS)
    frames_[0].save(
        out, save_all=True, append_images=frames_[1:], duration=durations, loop=0, disposal=1
    )
    return out


def write_mp4(images: Iterable[np.ndarray], out: Path, fps: float) -> Path:
    writer = None
    try:
        for image in images:
            if writer is None:
                height, width = image.shape[:2]
                fourcc = cv2.VideoWriter_fourcc(*"mp4v")
                writer = cv2.VideoWriter(str(out), fourcc, fps, (width, height))
                if not writer.isOpened():
                    raise ReplayError(
                        f"no MP4 encoder in this OpenCV build ({cv2.__version__}): use "
                        "--format gif or html instead"
                    )
            writer.write(image)
    finally:
        if writer is not None:
            writer.release()
    return out
