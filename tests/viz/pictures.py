"""Helpers for the picture tests: read a PNG back and measure how much it shows."""

import numpy as np


def read_png(path):
    """``(H, W, channels)`` uint8 pixels of a PNG; fails unless the file is a valid PNG."""
    from PIL import Image
    with open(path, "rb") as f:
        assert f.read(8) == b"\x89PNG\r\n\x1a\n", f"{path} is not a PNG"
    with Image.open(path) as im:
        im.verify()
    with Image.open(path) as im:
        return np.asarray(im.convert("RGB"))


def distinct_colours(img):
    return len(np.unique(img.reshape(-1, img.shape[-1]), axis=0))


def drawn_fraction(img, background=(255, 255, 255)):
    """Fraction of pixels that differ from the background colour."""
    return float(np.mean(np.any(img[..., :3] != np.asarray(background), axis=-1)))


def changed_fraction(a, b):
    """Fraction of pixels that differ between two images of the same size."""
    assert a.shape == b.shape
    return float(np.mean(np.any(a != b, axis=-1)))
