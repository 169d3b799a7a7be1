"""What a reader needs beside a drawn state: the environment, the step and the score.

Environment renderers draw only the state; this layer scales their frames to
a legible size and adds the caption strip, the same for every environment,
so that figures and GIFs say what they show.
"""

from __future__ import annotations

import math

import numpy as np

LEGIBLE = (480, 640)  # the long side of a legible frame, in pixels
MAX_CRISP = 720  # an integer (crisp) upscale may overshoot LEGIBLE up to here
CAPTION_FONT_SIZE = 18
MIN_FONT_SIZE = 10
CAPTION_PADDING = 8
CAPTION_BACKGROUND = (245, 245, 245)
CAPTION_TEXT = (20, 20, 20)
TITLES = {
    "tsp": "TSP", "flp": "FLP (k-center)", "flp-mean": "FLP (k-median)", "collect": "Collect", "2048": "2048",
    "pacman": "Pac-Man", "pacman-po": "Pac-Man (partial view)", "sokoban": "Sokoban",
}


def title(env_name: str) -> str:
    """The environment as a figure names it."""
    return TITLES.get(env_name, env_name)


def format_score(score: float) -> str:
    """Whole scores (coins, game points) without decimals, others (tour lengths) to three."""
    score = float(score)
    return str(int(score)) if score.is_integer() else f"{score:.3f}"


def tsp_measures(state, final: bool) -> str:
    """The tour length so far; on the final frame also the optimum (nearest neighbour past Held-Karp's reach)."""
    from pizero_ray.envs import tsp

    length = tsp.placed_path_length(state)
    if not final:
        return f"tour length so far {length:.3f}"
    coordinates = np.asarray(state.coordinates, dtype=np.float64)
    if len(coordinates) > tsp.MAX_EXACT_CITIES:
        greedy = float(tsp.nearest_neighbour_tour_length(coordinates))
        return f"tour length {length:.3f}  ·  nearest neighbour {greedy:.3f}"
    optimal = float(tsp.optimal_tour_length(coordinates))
    gap = max(0.0, 100 * (length / optimal - 1))  # never below 0 but for rounding: no "-0.0%"
    return f"tour length {length:.3f}  ·  optimal {optimal:.3f} (+{gap:.1f}%)"


def flp_measures(state, objective: str) -> str:
    """The objective of the facilities placed so far: covering radius (max) or mean distance (mean)."""
    from pizero_ray.envs import flp

    placed = np.asarray(state.facilities)[:int(state.t)]
    name = "covering radius" if objective == "max" else "mean distance"
    if not len(placed):
        return f"{name}: no facility yet"
    return f"{name} {float(flp.cost(np.asarray(state.clients), placed, objective)):.3f}"


def measures(env_name: str, state, final: bool) -> list[str]:
    """What the score alone does not say, for the environments whose score is paid only at the end."""
    if env_name == "tsp":
        return [tsp_measures(state, final)]
    if env_name in ("flp", "flp-mean"):
        return [flp_measures(state, "max" if env_name == "flp" else "mean")]
    return []


def caption_lines(env_name: str, state, step: int, horizon: int, score: float, final: bool) -> list[str]:
    """The caption of one frame: environment, step t / horizon and score so far, then any measures.

    Every frame of an environment gets the same number of lines, so a GIF's frames are the same size.
    """
    head = f"{title(env_name)}  ·  step {step}/{horizon}  ·  score {format_score(score)}"
    return [head, *measures(env_name, state, final)]


def legible(frame: np.ndarray) -> np.ndarray:
    """``frame`` scaled so its long side is about LEGIBLE: by a whole factor (crisp cells) where that
    lands at most MAX_CRISP, smoothly to LEGIBLE's top otherwise."""
    from PIL import Image

    height, width = frame.shape[:2]
    long_side = max(height, width)
    factor = max(1, math.ceil(LEGIBLE[0] / long_side))
    if long_side * factor <= MAX_CRISP:
        return np.asarray(Image.fromarray(frame).resize((width * factor, height * factor), Image.NEAREST))
    ratio = LEGIBLE[1] / long_side
    size = (round(width * ratio), round(height * ratio))
    return np.asarray(Image.fromarray(frame).resize(size, Image.LANCZOS))


def _fitting_font(draw, lines: list[str], width: int):
    """The largest font up to CAPTION_FONT_SIZE in which every line fits ``width`` (else the smallest)."""
    from PIL import ImageFont

    for size in range(CAPTION_FONT_SIZE, MIN_FONT_SIZE, -1):
        font = ImageFont.load_default(size=size)
        if all(draw.textlength(line, font=font) <= width for line in lines):
            return font
    return ImageFont.load_default(size=MIN_FONT_SIZE)


def annotate(frame: np.ndarray, lines: list[str]) -> np.ndarray:
    """``frame`` made legible, with ``lines`` in a caption strip below it."""
    from PIL import Image, ImageDraw

    frame = legible(frame)
    height, width = frame.shape[:2]
    scratch = ImageDraw.Draw(Image.new("RGB", (1, 1)))
    font = _fitting_font(scratch, lines, width - 2 * CAPTION_PADDING)
    line_height = round(1.35 * CAPTION_FONT_SIZE)  # not the fitted font's: every frame's strip is the same height
    strip = len(lines) * line_height + 2 * CAPTION_PADDING
    image = Image.new("RGB", (width, height + strip), CAPTION_BACKGROUND)
    image.paste(Image.fromarray(frame), (0, 0))
    draw = ImageDraw.Draw(image)
    for i, line in enumerate(lines):
        draw.text((CAPTION_PADDING, height + CAPTION_PADDING + i * line_height), line, fill=CAPTION_TEXT, font=font)
    return np.asarray(image)
