"""The renderers' shared header canvas: the board below a strip of text that stays in its strip."""

import numpy as np
import pytest
from PIL import ImageDraw

from pizero_ray.envs import collect, game2048, pacman, sokoban
from pizero_ray.envs.rendering import Header, canvas_with_header, font

HEADER = Header(height=22, text_origin=(4, 3), font_size=14, text_colour=(250, 0, 0))


def test_canvas_is_the_board_below_the_header_with_the_text_in_the_header():
    image, draw = canvas_with_header(120, 50, (0, 0, 40), HEADER, "goals 1/2  frightened")
    pixels = np.asarray(image)
    assert pixels.shape == (22 + 50, 120, 3)
    assert (pixels[HEADER.height:] == (0, 0, 40)).all()  # the board is the renderer's, still blank
    assert (pixels[:HEADER.height] == (250, 0, 0)).all(axis=-1).any()  # the text, in its colour
    draw.rectangle((0, HEADER.height, 9, HEADER.height + 9), fill=(0, 255, 0))  # the returned draw paints the image
    assert tuple(np.asarray(image)[HEADER.height, 0]) == (0, 255, 0)


def test_the_header_font_is_drawn_at_the_size_asked_for():
    heights = {}
    for size in (14, 22):
        _, top, _, bottom = ImageDraw.Draw(canvas_with_header(200, 1, "white", HEADER, "")[0]).textbbox(
            (0, 0), "Hg", font=font(size))
        heights[size] = bottom - top
    assert 12 <= heights[14] < heights[22] <= 26  # the glyphs span about the size in pixels


# the longest header each renderer writes: the text is drawn before the board, so it must not reach into it
LONGEST_HEADERS = [
    (collect.HEADER, "coins left 99"),
    (pacman.HEADER, "pellets left 244  frightened"),
    (sokoban.HEADER, "goals 4/4  solved  level 99999"),
    (game2048.HEADER, "highest tile 131072"),
]


@pytest.mark.parametrize("header, text", LONGEST_HEADERS)
def test_every_renderers_header_text_stays_in_its_strip(header, text):
    image, _ = canvas_with_header(600, 10, "white", header, "")
    _, top, _, bottom = ImageDraw.Draw(image).textbbox(header.text_origin, text + "gjpqy", font=font(header.font_size))
    assert 0 <= top and bottom <= header.height
