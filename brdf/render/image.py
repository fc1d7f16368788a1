"""Images: OpenEXR and PNG reading and writing, tone mapping, and image-difference metrics."""

import math
import os
from pathlib import Path

import numpy as np

from ..errors import FormatError, InputError
from ..io.files import openexr

#: Layers holding vectors, whose channels are named X, Y, Z
_VECTOR_LAYERS = {"normal", "position"}

__all__ = ["read_image", "write_exr", "write_png", "tonemap", "false_colour", "metrics",
           "luminance", "difference_scale", "flip_error", "magma", "DIFFERENCE_PERCENTILE"]

#: Percentile of |difference| that a false-colour difference shows at full colour; the larger
#: differences (a noisy pixel, a silhouette) are clipped there.
DIFFERENCE_PERCENTILE = 99.0


def _srgb_decode(c):
    """sRGB electro-optical transfer function (IEC 61966-2-1:1999), 8-bit code / 255 -> linear."""
    return np.where(c <= 0.04045, c / 12.92, ((c + 0.055) / 1.055) ** 2.4)


def _srgb_encode(c):
    """Inverse of :func:`_srgb_decode` (IEC 61966-2-1:1999)."""
    c = np.clip(c, 0.0, 1.0)
    return np.where(c <= 0.0031308, 12.92 * c, 1.055 * c ** (1.0 / 2.4) - 0.055)


#: Largest image file read: 4 GB (a 16384 x 16384 float32 RGBA EXR, uncompressed).
IMAGE_BYTES = 4 << 30


def read_image(source, what="image", channels=None, srgb=True):
    """A float image ``(h, w, c)`` from an EXR or PNG path or an array.

    EXR values are taken as they are (linear); 8- or 16-bit PNG values are scaled to [0, 1]
    and, with ``srgb``, decoded from sRGB to linear. ``channels=3`` expands grey to RGB and
    drops alpha.
    """
    if isinstance(source, (str, os.PathLike)):
        path = Path(source)
        if not path.exists():
            raise InputError(f"{path}: {what}: no such file")
        from ..io.files import check_file
        check_file(path, IMAGE_BYTES, f"an image ({what})")
        suffix = path.suffix.lower()
        if suffix == ".exr":
            img = _read_exr(path)
        elif suffix == ".png":
            img = _read_png(path, srgb)
        else:
            raise InputError(f"{path}: {what}: expected an .exr or .png file")
    else:
        img = np.asarray(source, dtype=float)
        path = what
    if img.ndim == 2:
        img = img[..., None]
    if img.ndim != 3 or img.shape[0] < 1 or img.shape[1] < 1:
        raise InputError(f"{path}: {what}: expected an image (h, w[, c]), got shape {img.shape}")
    if not np.all(np.isfinite(img)):
        raise FormatError(path, "", f"{what}: holds NaN or infinite values")
    if channels == 3:
        img = np.repeat(img[..., :1], 3, axis=2) if img.shape[2] < 3 else img[..., :3]
    return np.ascontiguousarray(img, dtype=float)


def _read_exr(path):
    OpenEXR = openexr()
    try:
        # the channels are only readable while the file is open
        with OpenEXR.File(str(path)) as f:
            ch = f.channels()
            key = next((k for k in ("RGB", "RGBA", "Y") if k in ch), next(iter(ch), None))
            if key is None:
                raise FormatError(path, "", "holds no channels")
            return np.array(ch[key].pixels, dtype=float)
    except FormatError:
        raise
    except Exception as e:  # OpenEXR raises RuntimeError or OSError for damaged files
        raise FormatError(path, "", f"not a readable OpenEXR file ({e})") from None


def _read_png(path, srgb):
    from PIL import Image
    try:
        with Image.open(path) as im:
            im.load()
            arr = np.asarray(im)
            mode = im.mode
    except Exception as e:  # Pillow raises several types for damaged files
        raise FormatError(path, "", f"not a readable PNG file ({e})") from None
    scale = 65535.0 if arr.dtype == np.uint16 or mode.startswith("I;16") else 255.0
    img = arr.astype(float) / scale
    if srgb:
        colour = img if img.ndim == 2 else img[..., :3]
        decoded = _srgb_decode(colour)
        img = decoded if img.ndim == 2 else np.concatenate([decoded, img[..., 3:]], axis=2)
    return img


def write_exr(path, rgb, layers=None, force=False):
    """Write float32 RGB (``(h, w, 3)``) and optional named layers (``{"albedo": (h, w, 3),
    "normal": (h, w, 3), "variance": (h, w, 3)}``, stored as ``albedo.R`` ..., ``normal.X`` ...)
    to an OpenEXR file, atomically; an existing file is replaced only with ``force``."""
    OpenEXR = openexr()
    from ..io import atomic_output
    channels = {"RGB": np.ascontiguousarray(rgb, dtype=np.float32)}
    for name, arr in (layers or {}).items():
        arr = np.asarray(arr, dtype=np.float32)
        if name in _VECTOR_LAYERS and arr.ndim == 3:
            # directions are x, y, z (the convention of renderers' AOVs), not colours
            for c, axis in enumerate("XYZ"):
                channels[f"{name}.{axis}"] = np.ascontiguousarray(arr[..., c])
        else:
            channels[name] = np.ascontiguousarray(arr)
    header = {"compression": OpenEXR.ZIP_COMPRESSION, "type": OpenEXR.scanlineimage}
    with atomic_output(path, force) as tmp:
        OpenEXR.File(header, channels).write(str(tmp))
    return Path(path)


def tonemap(rgb, exposure=0.0):
    """Linear radiance to 8-bit sRGB: scale by 2^exposure, clip, sRGB-encode. ``exposure`` is
    a finite number of stops within +-64 (beyond, every pixel is black or white)."""
    try:
        stops = float(exposure)
    except (TypeError, ValueError):
        stops = math.nan
    if not (math.isfinite(stops) and -64.0 <= stops <= 64.0):
        raise InputError(f"exposure: expected a finite number of stops in [-64, 64], got "
                         f"{exposure!r}")
    return np.round(_srgb_encode(np.asarray(rgb, float) * 2.0 ** exposure) * 255.0).astype(
        np.uint8)


def write_png(path, image, force=False):
    """Write an 8-bit image ``(h, w, 3)`` as PNG, atomically."""
    from PIL import Image
    from ..io import atomic_output
    with atomic_output(path, force) as tmp:
        Image.fromarray(np.asarray(image, np.uint8)).save(tmp, format="PNG")
    return Path(path)


def luminance(rgb):
    """Relative luminance ``(h, w)`` of linear RGB ``(h, w, 3)`` (Rec. 709 weights); a single
    channel ``(h, w)`` is returned as it is."""
    d = np.asarray(rgb, float)
    return d @ np.array([0.2126, 0.7152, 0.0722]) if d.ndim == 3 else d


def difference_scale(diff):
    """The magnitude a false-colour difference shows at full colour: the
    :data:`DIFFERENCE_PERCENTILE`-th percentile of the luminance's |diff| (1 when that is 0)."""
    return float(np.percentile(np.abs(luminance(diff)), DIFFERENCE_PERCENTILE)) or 1.0


def false_colour(diff, scale=None):
    """A signed difference image as 8-bit RGB: blue where negative, red where positive, white
    at 0 (luminance of ``diff``); ``scale`` is the magnitude shown at full colour (default
    :func:`difference_scale`), larger magnitudes are clipped to it."""
    d = luminance(diff)
    if scale is None:
        scale = difference_scale(d)
    t = np.clip(d / scale, -1.0, 1.0)
    r = np.where(t < 0, 1.0 + t, 1.0)
    b = np.where(t > 0, 1.0 - t, 1.0)
    g = 1.0 - np.abs(t)
    return np.round(np.stack([r, g, b], axis=-1) * 255.0).astype(np.uint8)


def flip_error(test, reference):
    """NVIDIA's HDR-FLIP (Andersson et al. 2021, the ``flip-evaluator`` package) of linear RGB
    ``test`` against ``reference``: ``(mean, error)``, the per-pixel error ``(h, w)`` in
    [0, 1]. Negative radiance counts as 0."""
    import flip_evaluator
    error, mean, _ = flip_evaluator.evaluate(
        np.ascontiguousarray(np.maximum(reference, 0.0), np.float32),
        np.ascontiguousarray(np.maximum(test, 0.0), np.float32), "HDR", applyMagma=False)
    return float(mean), np.clip(np.asarray(error, float).reshape(error.shape[:2]), 0.0, 1.0)


def magma(values):
    """Values in [0, 1] ``(h, w)`` as 8-bit RGB through matplotlib's magma colour map (FLIP's
    own: black at 0, pale yellow at 1)."""
    from matplotlib import colormaps
    rgb = colormaps["magma"](np.clip(np.asarray(values, float), 0.0, 1.0))[..., :3]
    return np.round(rgb * 255.0).astype(np.uint8)


def metrics(test, reference, flip=True):
    """Image differences of ``test`` against ``reference`` (linear RGB ``(h, w, 3)``): RMSE,
    relative MSE (mean of (t - r)^2 / (r^2 + 0.01), Rousselle et al. 2011's denoising metric)
    and the HDR-FLIP mean (:func:`flip_error`). Returns ``(metrics, flip_map)``, the map an
    8-bit magma image of the per-pixel FLIP error (None without ``flip``)."""
    t = np.asarray(test, float)
    r = np.asarray(reference, float)
    if t.shape != r.shape:
        raise InputError(f"images differ in shape: {t.shape} and {r.shape}")
    d = t - r
    out = {"rmse": float(np.sqrt(np.mean(d * d))),
           "relmse": float(np.mean(d * d / (r * r + 0.01))),
           "mean_test": [float(x) for x in t.reshape(-1, t.shape[-1]).mean(axis=0)],
           "mean_reference": [float(x) for x in r.reshape(-1, r.shape[-1]).mean(axis=0)]}
    flip_map = None
    if flip:
        out["flip"], error = flip_error(t, r)
        flip_map = magma(error)
    return out, flip_map
