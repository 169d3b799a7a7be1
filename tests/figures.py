"""Checks that a written PNG shows what it should, not just that it is a PNG: its size in pixels, and the
pixels its data drew (a figure whose plotting code drew nothing has the right header, and fails these).

Not a test module, so pytest does not rewrite its asserts: each says what it saw itself."""

from pathlib import Path

import numpy as np

# Pixels of a curve's colour one panel must hold. The legend's handle and a lone marker draw about 100 pixels
# of it; a line between two points far apart on a learning-curve panel draws several hundred.
CURVE_PIXELS = 200
COLOUR_TOLERANCE = 0.1  # per channel, in 0..1: a line's antialiased edge is off its colour, its middle is not


def read_rgb(path: Path) -> np.ndarray:
    """The PNG at ``path`` as [height, width, 3] floats in 0..1 (any alpha dropped)."""
    import matplotlib.image

    image = np.asarray(matplotlib.image.imread(path), dtype=np.float64)
    assert image.ndim == 3 and image.shape[2] in (3, 4), f"{path.name} is not an RGB(A) image: {image.shape}"
    return image[..., :3]


def colour_pixels(image: np.ndarray, colour) -> int:
    """How many pixels of ``image`` are ``colour`` (a matplotlib colour: "C0", "#1f77b4", or 0..255 RGB)."""
    from matplotlib.colors import to_rgb

    if isinstance(colour, tuple) and max(colour) > 1:
        rgb = np.asarray(colour, dtype=np.float64) / 255.0
    else:
        rgb = np.asarray(to_rgb(colour))
    return int((np.abs(image - rgb).max(axis=-1) <= COLOUR_TOLERANCE).sum())


def colourful_pixels(image: np.ndarray, saturation: float = 0.25) -> int:
    """How many pixels are coloured: neither the white background nor black or grey text, axes and grids."""
    return int((image.max(axis=-1) - image.min(axis=-1) >= saturation).sum())


def columns(image: np.ndarray, count: int) -> list[np.ndarray]:
    """``image`` cut into ``count`` equal vertical strips: a figure's panels side by side."""
    width = image.shape[1]
    return [image[:, width * i // count:width * (i + 1) // count] for i in range(count)]


def assert_curves_drawn(path: Path, size: tuple[int, int], panels: list[tuple[str, ...]]) -> None:
    """The figure at ``path`` is ``size`` (width, height) pixels, and its panels, side by side, each hold a line
    drawn in every colour listed for it (the curves' matplotlib colours: "C0" for the first curve)."""
    image = read_rgb(path)
    assert (image.shape[1], image.shape[0]) == size, f"{path.name} is {image.shape[1]} x {image.shape[0]}, not {size}"
    for index, (panel, colours) in enumerate(zip(columns(image, len(panels)), panels)):
        drawn = {colour: colour_pixels(panel, colour) for colour in colours}
        assert all(count >= CURVE_PIXELS for count in drawn.values()), (
            f"panel {index} of {path.name} has too few pixels of a curve's colour: {drawn}")
