"""What the environments' renderers share: a canvas with a line of text above the board.

2048, Collect, Pac-Man and Sokoban draw their board below a header strip that
says how the game stands (highest tile, coins or pellets left, goals covered).
PIL is imported inside the functions: rendering is off the jitted path, and an
environment need not load it to be built.
"""

from __future__ import annotations

import functools
from typing import Any, NamedTuple


class Header(NamedTuple):
    """How a renderer's header strip looks: its height and where and how its text is drawn."""

    height: int  # pixels above the board
    text_origin: tuple[int, int]  # (x, y) of the text's top left, in the image
    font_size: int
    text_colour: Any  # a PIL colour: an (r, g, b) tuple or a name


@functools.lru_cache(maxsize=None)
def font(size: int):
    """PIL's default font at ``size`` pixels, loaded once per size (a renderer asks for it on every frame)."""
    from PIL import ImageFont

    return ImageFont.load_default(size=size)


def canvas_with_header(width: int, board_height: int, background, header: Header, text: str):
    """(image, draw): a ``background`` RGB image, ``width`` x ``header.height + board_height``, ``text`` in its header.

    The board is the renderer's to draw, from ``y = header.height`` down. The
    text is drawn first; that is safe because it stays within its strip.
    """
    from PIL import Image, ImageDraw

    image = Image.new("RGB", (width, header.height + board_height), background)
    draw = ImageDraw.Draw(image)
    draw.text(header.text_origin, text, fill=header.text_colour, font=font(header.font_size))
    return image, draw
