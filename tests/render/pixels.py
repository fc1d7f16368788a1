"""Camera rays of the path tracer's pixel centres, and where they meet a plane, for tests that
compare renders with closed-form radiance."""

import numpy as np


def pixel_directions(camera, w, h):
    """Unit directions of the rays through pixel centres (as the renderer builds them)."""
    cam = camera.pack(w, h)
    x = (np.arange(w) + 0.5) / w * 2 - 1
    y = 1 - (np.arange(h) + 0.5) / h * 2
    X, Y = np.meshgrid(x, y)
    d = cam[3:6] + X[..., None] * cam[6:9] + Y[..., None] * cam[9:12]
    return d / np.linalg.norm(d, axis=-1, keepdims=True)


def hits_on_ground(camera, w, h):
    """Pixel-centre rays meeting the plane y = 0: directions (h, w, 3) and points (h, w, 3)."""
    d = pixel_directions(camera, w, h)
    o = np.array(camera.origin, float)
    t = -o[1] / d[..., 1]
    return d, o + t[..., None] * d


def ground_local(v):
    """World directions in the local frame of the built-in plane (normal +y, tangent +x along
    edge1, bitangent n x t = -z)."""
    return np.stack([v[..., 0], -v[..., 2], v[..., 1]], axis=-1)
