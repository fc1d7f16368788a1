"""Views of a capture: a scene file, the photograph of it and an optional mask, read and checked.

A view is one photograph of a known scene (:func:`brdf.render.load`'s JSON or TOML format):
the image's width and height are the render size and the scene's camera took it. Shapes whose
material is ``"@material"`` carry the unknown BRDF; every other material, the geometry and the
lights are known. Pixels used are those of the mask (a PNG, non-zero where used, or the EXR's
alpha above one half), minus saturated pixels (a channel at the top code of an 8- or 16-bit
file), which hold a lower bound only.

Images: OpenEXR RGB or RGBA (linear, float); 8-bit PNG RGB(A) through Pillow; 8- or 16-bit
TIFF RGB(A) through tifffile (the 16-bit linear TIFFs raw developers write); decoded to linear
by a :mod:`~brdf.capture.responses` response. Pillow reads 16-bit RGB PNGs as 8-bit, so those
are refused (save them as TIFF or EXR) rather than read at the wrong depth.
"""

import os
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from ..errors import FormatError, InputError
from ..io.files import openexr
from .responses import response as _response

__all__ = ["View", "read_view", "read_photo", "Photo", "MATERIAL_MARK"]

#: The material name in a scene file that marks the shapes of the unknown BRDF.
MATERIAL_MARK = "@material"
#: Largest image read (a 16384 x 16384 float32 RGBA EXR).
IMAGE_BYTES = 4 << 30
_PHOTO_SUFFIXES = (".png", ".tif", ".tiff")


@dataclass
class Photo:
    """An image decoded to linear values.

    Attributes
    ----------
    path : str
    linear : ndarray (h, w, 3)
        Linear RGB values.
    alpha : ndarray (h, w) or None
        The file's alpha in [0, 1], when it has one.
    step : ndarray (h, w, 3) or None
        Linear width of one code step at each value (8- or 16-bit files), None for floats.
    saturated : ndarray (h, w) of bool
        Pixels with a channel at the file's top code.
    bits : int or None
        Bits per channel of an integer file.
    response : Response
    """

    path: str
    linear: np.ndarray
    alpha: object
    step: object
    saturated: np.ndarray
    bits: object
    response: object


def _png_depth(path):
    """Bit depth and colour type from a PNG's IHDR chunk, or None when not a PNG."""
    with open(path, "rb") as f:
        head = f.read(33)
    if len(head) < 33 or head[:8] != b"\x89PNG\r\n\x1a\n" or head[12:16] != b"IHDR":
        return None
    return head[24], head[25]


def read_photo(path, response="linear"):
    """A :class:`Photo` from an EXR (linear only), PNG or TIFF file; FormatError or InputError
    naming the file for anything else (grey images, other channel counts, NaN, damaged
    files)."""
    from ..io.files import check_file
    path = os.fspath(path)
    resp = _response(response)
    if not Path(path).exists():
        raise InputError(f"{path}: image: no such file")
    check_file(path, IMAGE_BYTES, "an image")
    suffix = Path(path).suffix.lower()
    if suffix == ".exr":
        if resp.name != "linear":
            raise InputError(f"{path}: an OpenEXR image holds linear values; --response "
                             f"{resp} is for 8- or 16-bit PNG/TIFF photographs")
        rgb, alpha = _read_exr(path)
        if not np.all(np.isfinite(rgb)):
            bad = np.argwhere(~np.isfinite(rgb))[0]
            raise FormatError(path, f"pixel (x={bad[1]}, y={bad[0]})",
                              "finite values (it holds NaN or infinity)")
        return Photo(path, rgb, alpha, None, np.zeros(rgb.shape[:2], bool), None, resp)
    if suffix not in _PHOTO_SUFFIXES:
        raise InputError(f"{path}: expected an OpenEXR (.exr), PNG or TIFF image")
    codes, top, alpha = _read_integer(path)
    c = codes / top
    linear = resp.decode(c)
    step = resp.slope(c) / top
    saturated = np.any(codes >= top, axis=2)
    bits = 8 if top == 255.0 else 16
    return Photo(path, linear, alpha, step, saturated, bits, resp)


def _read_exr(path):
    OpenEXR = openexr()
    try:
        with OpenEXR.File(str(path)) as f:
            ch = f.channels()
            names = set(ch)
            if "RGBA" in names:
                px = np.array(ch["RGBA"].pixels, dtype=float)
                return px[..., :3], np.clip(px[..., 3], 0.0, 1.0)
            if "RGB" in names:
                alpha = np.array(ch["A"].pixels, dtype=float) if "A" in names else None
                return np.array(ch["RGB"].pixels, dtype=float), alpha
    except Exception as e:  # OpenEXR raises RuntimeError or OSError for damaged files
        raise FormatError(path, "", f"a readable OpenEXR file ({' '.join(str(e).split())})") \
            from None
    raise FormatError(path, "channels", f"R, G and B channels (it has {', '.join(sorted(names))})")


def _read_tiff(path):
    """Codes (h, w, 3) as floats, the top code, and alpha or None, from an 8- or 16-bit RGB(A)
    TIFF through tifffile (Pillow reads 16-bit RGB TIFFs at 8 bits, or not at all)."""
    import tifffile
    try:
        arr = np.asarray(tifffile.imread(path))
    except Exception as e:  # tifffile raises several types for damaged files
        raise FormatError(path, "", f"a readable TIFF file ({' '.join(str(e).split())})") \
            from None
    if arr.ndim == 3 and arr.shape[0] in (3, 4) and arr.shape[2] not in (3, 4):
        arr = np.moveaxis(arr, 0, 2)  # planar configuration: channels first
    if arr.ndim != 3 or arr.shape[2] not in (3, 4):
        raise FormatError(path, "", f"an RGB(A) image; its samples are shaped {arr.shape}")
    if arr.dtype == np.uint8:
        top = 255.0
    elif arr.dtype == np.uint16:
        top = 65535.0
    else:
        raise FormatError(path, "", f"8- or 16-bit integer samples (a float TIFF: save it as "
                                    f"OpenEXR), got {arr.dtype}")
    arr = arr.astype(float)
    return arr[..., :3], top, (arr[..., 3] / top if arr.shape[2] == 4 else None)


def _read_integer(path):
    """Codes (h, w, 3) as floats, the top code, and alpha in [0, 1] or None."""
    from PIL import Image
    if Path(path).suffix.lower() in (".tif", ".tiff"):
        return _read_tiff(path)
    depth = _png_depth(path)
    if depth is not None and depth[0] == 16 and depth[1] in (2, 6):
        raise FormatError(path, "IHDR", "an 8-bit RGB PNG (Pillow reads 16-bit RGB PNGs as "
                                        "8 bits); save a 16-bit photograph as TIFF or OpenEXR")
    try:
        with Image.open(path) as im:
            im.load()
            mode = im.mode
            arr = np.asarray(im)
    except Exception as e:  # Pillow raises several types for damaged files
        raise FormatError(path, "", f"a readable image ({' '.join(str(e).split())})") from None
    if mode in ("RGB", "RGBA"):
        top = 255.0
    elif mode.startswith("I;16") or mode in ("L", "LA", "I", "P", "1"):
        raise FormatError(path, "", f"an RGB image; it is {mode} (grey or palette): save the "
                                    "photograph as RGB")
    else:
        raise FormatError(path, "", f"an 8-bit RGB(A) image; Pillow reads it as mode {mode}")
    arr = arr.astype(float)
    alpha = arr[..., 3] / top if arr.shape[2] == 4 else None
    return arr[..., :3], top, alpha


def _read_mask(path, shape):
    """Boolean mask from a PNG (non-zero in any channel); FormatError for another size."""
    from PIL import Image
    path = os.fspath(path)
    if not Path(path).exists():
        raise InputError(f"{path}: mask: no such file")
    try:
        with Image.open(path) as im:
            im.load()
            arr = np.asarray(im)
    except Exception as e:
        raise FormatError(path, "", f"a readable PNG mask ({' '.join(str(e).split())})") from None
    h, w = arr.shape[:2]
    if (h, w) != tuple(shape):
        raise FormatError(path, "size", f"a mask of the image's size {shape[1]} x {shape[0]}, "
                                        f"got {w} x {h}")
    if arr.ndim == 3:
        arr = arr[..., :3] if arr.shape[2] >= 3 else arr[..., :1]
        return np.any(arr > 0, axis=2)
    return arr > 0


@dataclass
class View:
    """One view of a capture, read and checked (:func:`read_view`).

    Attributes
    ----------
    scene : brdf.render.Scene
        The scene, with :attr:`marker` as the material of its ``@material`` shapes.
    marker : brdf.render.Material
        The placeholder material of the unknown BRDF's shapes.
    photo : Photo
    mask : ndarray (h, w) of bool
        Pixels the user allows (mask file or alpha; all when neither), saturation not yet
        taken out.
    scene_path, mask_path : str or None
    """

    scene: object
    marker: object
    photo: Photo
    mask: np.ndarray
    scene_path: object
    mask_path: object

    @property
    def size(self):
        h, w = self.photo.linear.shape[:2]
        return w, h

    @property
    def material_shapes(self):
        return [k for k, s in enumerate(self.scene.shapes) if s.material is self.marker]


def read_view(scene, image, mask=None, response="linear"):
    """Read one view: ``scene`` a scene file (or a :class:`brdf.render.Scene` whose unknown
    shapes carry the material ``"@material"``), ``image`` its photograph, ``mask`` an optional
    PNG of the same size. Errors are one line naming the file."""
    from ..render import Material, Scene, load
    marker = Material("lambert(albedo=0.5)", name=MATERIAL_MARK)
    if isinstance(scene, Scene):
        import copy
        sc = copy.copy(scene)
        sc.shapes = [copy.copy(s) for s in scene.shapes]
        for s in sc.shapes:
            if isinstance(s.material, str) and s.material == MATERIAL_MARK:
                s.material = marker
        where = scene.source or "scene"
    else:
        sc = load(scene, material=marker)
        where = os.fspath(scene)
    if not any(s.material is marker for s in sc.shapes):
        raise FormatError(where, "shapes", f'a shape whose material is "{MATERIAL_MARK}" (the '
                                           "unknown BRDF); none has it")
    photo = read_photo(image, response)
    h, w = photo.linear.shape[:2]
    if mask is not None:
        allowed = _read_mask(mask, (h, w))
    elif photo.alpha is not None:
        allowed = photo.alpha > 0.5
    else:
        allowed = np.ones((h, w), dtype=bool)
    view = View(sc, marker, photo, allowed, where, None if mask is None else os.fspath(mask))
    try:
        sc.camera.pack(w, h)
    except InputError as e:
        raise FormatError(where, "camera", str(e)) from None
    return view
