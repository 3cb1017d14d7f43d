"""Clips as looping animated GIFs, each frame marked with what a person needs to judge it.

A preference query shows one GIF per candidate, each rendered once per session (`CandidateClips`); the
task before and after a session is one GIF of two clips side by side (`side_by_side_gif`).

Without marks a desk guessed too low (the sponge pressing too hard) looks like normal wiping, and a cube
stopping short of an unmarked goal looks like any push. So each wiping frame carries a gauge of the contact
force with the safe band, and each pushing frame a strip of the cube's way to its goal (`annotated_frames`).
"""

from __future__ import annotations

import io
from collections.abc import Callable, Sequence
from functools import partial
from typing import Any

import numpy as np
from PIL import Image, ImageDraw, ImageFont

from hipref.control.tool import FORCE_Z
from hipref.envs.pushing import PushingTask
from hipref.envs.task import Layout, evenly_spaced
from hipref.envs.wiping import WipingTask

GAP = 8
"""Pixels of white between the two clips."""
GAUGE_TOP = 2.0
"""The force gauge's scale ends at this multiple of the safe band's top (a force beyond it fills it)."""
Colour = tuple[int, int, int]
"""An RGB colour, 0-255."""
SAFE, HARD, OFF = (44, 160, 44), (214, 39, 40), (127, 127, 127)
"""Colours of a force inside the safe band, above it, below it (not touching)."""
WORDING: dict[Colour, Colour] = {SAFE: (0, 110, 0), HARD: (190, 20, 20), OFF: (80, 80, 80)}
"""The caption's lettering for each: darker, at least 4.5:1 against its white (the bars' colours are not)."""
GOAL, CUBE = (44, 160, 44), (51, 102, 230)
"""Colours of the pushing strip's goal mark and cube (the cube's colour in the scene, `hipref.sim.scene`)."""


FONT = ImageFont.load_default(size=14)
"""The marks' lettering: Pillow's own scalable font, at a size readable on a 320-pixel-wide clip."""


def label(draw: ImageDraw.ImageDraw, at: tuple[float, float], text: str, colour: Colour) -> None:
    """`text` with its top left at `at`, on white (the scenes are dark)."""
    left, top, right, bottom = draw.textbbox(at, text, font=FONT)
    draw.rectangle((left - 3, top - 3, right + 3, bottom + 3), fill=(255, 255, 255))
    draw.text(at, text, fill=colour, font=FONT)


def caption(draw: ImageDraw.ImageDraw, text: str, colour: Colour) -> None:
    """`text` at the frame's top left, on white."""
    label(draw, (4, 4), text, colour)


def force_gauge(frame: np.ndarray, force: float, band: tuple[float, float]) -> np.ndarray:
    """`frame` with a vertical gauge of the contact force `force` (N) at its right edge, the safe `band`
    shaded green, and a caption: the force, and whether it is safe, too hard, or off (not touching)."""
    image = Image.fromarray(frame)
    draw = ImageDraw.Draw(image)
    height, width = frame.shape[:2]
    left, right, top, bottom = width - 26, width - 10, 22, height - 22
    low, high = band
    scale = GAUGE_TOP * high

    def level(f: float) -> float:
        return bottom - (bottom - top) * min(max(f, 0.0), scale) / scale

    draw.rectangle((left, top, right, bottom), fill=(255, 255, 255), outline=(0, 0, 0))
    draw.rectangle((left, level(high), right, level(low)), fill=(199, 233, 192))
    colour, words = (
        (SAFE, "safe") if low <= force <= high else (HARD, "too hard") if force > high else (OFF, "off")
    )
    draw.rectangle((left + 4, level(force), right - 4, bottom), fill=colour)
    mark = f"{high:g} N"  # the safe band's top, left of the gauge
    draw.line((left - 4, level(high), left, level(high)), fill=(255, 255, 255), width=1)
    label(draw, (left - 8 - draw.textlength(mark, font=FONT), level(high) - 8), mark, (0, 0, 0))
    caption(draw, f"contact force {max(force, 0.0):.0f} N: {words}", WORDING[colour])
    return np.asarray(image)


def push_strip(frame: np.ndarray, travelled: float, goal: float) -> np.ndarray:
    """`frame` with a strip along its bottom: the cube's way from its start (left) to its goal (a green
    mark), the cube where it is now (`travelled` m of the `goal` m), and how far it is from the goal."""
    image = Image.fromarray(frame)
    draw = ImageDraw.Draw(image)
    height, width = frame.shape[:2]
    y, start, end = height - 12, 12, width - 12
    span = 1.5 * goal  # room past the goal for an overshoot

    def x(distance: float) -> float:
        return start + (end - start) * min(max(distance, 0.0), span) / span

    draw.rectangle((0, height - 24, width, height), fill=(255, 255, 255))
    draw.line((start, y, end, y), fill=(0, 0, 0), width=1)
    draw.line((x(goal), y - 9, x(goal), y + 9), fill=GOAL, width=3)
    draw.rectangle((x(travelled) - 5, y - 5, x(travelled) + 5, y + 5), fill=CUBE, outline=(0, 0, 0))
    to_go = goal - travelled
    words = f"{to_go * 100:.0f} cm to the goal" if to_go >= 0 else f"{-to_go * 100:.0f} cm past the goal"
    caption(draw, f"cube: {words}", (0, 0, 0))
    return np.asarray(image)


Mark = Callable[[np.ndarray], np.ndarray]
"""What is drawn on one frame of a clip."""


def wiping_marks(task: WipingTask, truth: float, estimate: float, layout: Layout, frames: int) -> list[Mark]:
    """Per frame of the stroke's clip: the force gauge at that frame's contact force."""
    force = task.rollout(truth, estimate, layout).features[:, FORCE_Z]  # the clip's own stroke again
    band = task.config.force_band
    return [partial(force_gauge, force=float(f), band=band) for f in force[evenly_spaced(len(force), frames)]]


def pushing_marks(
    task: PushingTask, truth: float, estimate: float, layout: Layout, frames: int
) -> list[Mark]:
    """Per frame of the push's clip: the strip with the cube where it is in that frame."""
    start, goal = (np.asarray(point, float) for point in layout)
    task.reset(truth, start, goal)
    push = task.push(estimate)  # the clip's own push again
    distance = float(np.linalg.norm(goal - start))
    shown = push.cube_xy[evenly_spaced(len(push.features), frames)]
    travelled = (shown - start) @ ((goal - start) / distance)
    return [partial(push_strip, travelled=float(t), goal=distance) for t in travelled]


FRAME_MARKS: dict[str, Callable[[Any, float, float, Layout, int], list[Mark]]] = {
    "wiping": wiping_marks,
    "pushing": pushing_marks,
}
"""Per domain: what each frame of a clip is marked with, for a person to judge it."""


def annotated_frames(
    domain: str, task: Any, truth: float, estimate: float, layout: Layout, frames: int
) -> list[np.ndarray] | None:
    """The clip of pi^l executed with `estimate` from `layout` in a world at `truth`, as `frames` images
    marked as `FRAME_MARKS` says; None where no GL is."""
    images = task.clip_frames(truth, estimate, layout, frames)
    if images is None:
        return None
    marks = FRAME_MARKS[domain](task, truth, estimate, layout, frames)
    return [mark(image) for mark, image in zip(marks, images, strict=True)]


def side_by_side_gif(clips: Sequence[Sequence[np.ndarray]], fps: int) -> bytes:
    """The clips' frames (each a list of equal-sized RGB arrays, all of one length) placed left to right,
    encoded as a GIF that loops forever at `fps` frames per second.

    Each frame gets its own palette by fast octree quantisation (128 colours), which keeps the encoding of
    40 frames of 648 x 240 pixels under a fifth of a second."""
    lengths = {len(frames) for frames in clips}
    if len(lengths) != 1 or not lengths.pop():
        raise ValueError(f"clips must have the same positive number of frames, got {[len(c) for c in clips]}")
    images = []
    for frames in zip(*clips, strict=True):
        height = frames[0].shape[0]
        gap = np.full((height, GAP, 3), 255, dtype=np.uint8)
        row = np.concatenate([part for frame in frames for part in (frame, gap)][:-1], axis=1)
        images.append(Image.fromarray(row).quantize(colors=128, method=Image.Quantize.FASTOCTREE))
    buffer = io.BytesIO()
    duration = round(1000 / fps)
    images[0].save(buffer, format="GIF", save_all=True, append_images=images[1:], duration=duration, loop=0)
    return buffer.getvalue()


class CandidateClips:
    """Each candidate's clip as a looping GIF, rendered once in a session and shown again whenever a query
    asks that candidate: pi^l executed with it from the session's one display layout, in the world at the
    truth, its frames marked (`annotated_frames`). A person compares two candidates on the same motion from
    query to query, and after the first few queries the next pair needs no rendering.

    Only one thread may use it: it executes and renders on `task`."""

    def __init__(self, domain: str, task: Any, truth: float, layout: Layout, frames: int, fps: int) -> None:
        self.domain, self.task, self.truth, self.layout = domain, task, truth, layout
        self.frames, self.fps = frames, fps
        self.gifs: dict[float, bytes] = {}
        self.available = True
        """False once rendering failed (no GL): nothing more is tried."""

    def gif(self, estimate: float) -> bytes | None:
        """The clip of `estimate`, rendered now if it was not yet; None where no GL is."""
        if estimate not in self.gifs and self.available:
            frames = annotated_frames(self.domain, self.task, self.truth, estimate, self.layout, self.frames)
            if frames is None:
                self.available = False
            else:
                self.gifs[estimate] = side_by_side_gif([frames], self.fps)
        return self.gifs.get(estimate)
