"""Scenes for the path tracer: camera, shapes, materials, lights, and their compiled arrays.

A :class:`Scene` holds plain Python objects; :meth:`Scene.compile` validates them and packs
them into the flat arrays the numba kernels read (see ``_intersect``, ``_materials`` and
``_lights`` for the layouts). Positions are in scene units (metres, say), colours are RGB,
radiance in W/(m^2 sr), intensity in W/sr, irradiance in W/m^2.
"""

import hashlib
import json
import math
import threading
from collections import OrderedDict, namedtuple
from dataclasses import dataclass, field

import numpy as np

from ..errors import InputError
from . import _intersect as X
from . import _lights as L
from . import _materials as M
from .bvh import block_leaves, build_bvh, collapse

__all__ = ["Camera", "Sphere", "Quad", "Mesh", "box", "rectangle", "Material", "PointLight",
           "SpotLight", "DirectionalLight", "GoniometricLight", "Environment", "Scene"]


def _floats(x):
    """``x`` as a flat float array, or None when it holds something other than numbers."""
    try:
        return np.asarray(x, dtype=float).reshape(-1)
    except (TypeError, ValueError):
        return None


def _number(x, name):
    """``x`` as a finite float."""
    a = _floats(x)
    if a is None or a.shape != (1,) or not np.isfinite(a[0]):
        raise InputError(f"{name}: expected a finite number, got {x!r}")
    return float(a[0])


def _vec(x, name, n=3):
    a = _floats(x)
    if a is None or a.shape != (n,) or not np.all(np.isfinite(a)):
        raise InputError(f"{name}: expected {n} finite numbers, got {x!r}")
    return a


def rgb_value(x, name):
    """An RGB triple from one number (grey) or three, non-negative and finite."""
    a = _floats(x)
    if a is not None and a.size == 1:
        a = np.repeat(a, 3)
    if a is None or a.shape != (3,) or not np.all(np.isfinite(a)) or np.any(a < 0):
        raise InputError(f"{name}: expected one or three non-negative numbers, got {x!r}")
    return a


def _unit(x, name):
    a = _vec(x, name)
    n = np.linalg.norm(a)
    if n == 0:
        raise InputError(f"{name}: expected a nonzero direction, got {x!r}")
    return a / n


# --- camera -----------------------------------------------------------------------------------

@dataclass
class Camera:
    """Pinhole camera looking from ``origin`` at ``target``; ``fov`` in degrees along
    ``fov_axis`` ("x", "y", "smaller" or "larger", as Mitsuba 3's perspective sensor)."""

    origin: tuple = (0.0, 0.0, 4.0)
    target: tuple = (0.0, 0.0, 0.0)
    up: tuple = (0.0, 1.0, 0.0)
    fov: float = 40.0
    fov_axis: str = "x"

    def pack(self, width, height):
        """The kernels' camera (15 numbers): origin, unit forward, right and up scaled to the
        half-extents of the image plane at distance 1, a pixel's extent 2 / width and
        2 / height in that plane's [-1, 1] coordinates, and one unused slot."""
        o = _vec(self.origin, "camera origin")
        fwd = _unit(np.subtract(self.target, o), "camera target - origin")
        right = np.cross(fwd, _unit(self.up, "camera up"))
        if np.linalg.norm(right) < 1e-9:
            raise InputError("camera: up is parallel to the viewing direction")
        right /= np.linalg.norm(right)
        up = np.cross(right, fwd)
        if not 0.0 < _number(self.fov, "camera fov") < 180.0:
            raise InputError(f"camera fov: expected degrees in (0, 180), got {self.fov}")
        axis = {"smaller": "x" if width <= height else "y",
                "larger": "x" if width >= height else "y"}.get(self.fov_axis, self.fov_axis)
        if axis not in ("x", "y"):
            raise InputError(f"camera fov_axis: expected x, y, smaller or larger, got "
                             f"{self.fov_axis!r}")
        t = math.tan(math.radians(float(self.fov)) / 2.0)
        tx, ty = (t, t * height / width) if axis == "x" else (t * width / height, t)
        return np.concatenate([o, fwd, tx * right, ty * up, [2.0 / width, 2.0 / height, 0.0]])


# --- materials --------------------------------------------------------------------------------

@dataclass
class Material:
    """A BRDF for the renderer: a model, spec, fit report path or measured table, with optional
    textures ``{"lobe.param": image}`` (a path to an EXR or PNG, or an array (h, w[, c]));
    per-channel parameters read the image's channels, scalar ones its first channel. Values
    are clipped to the parameter's declared bounds. ``name`` labels it in error messages."""

    brdf: object
    textures: dict = field(default_factory=dict)
    name: str = field(default=None, compare=False)

    def resolve(self):
        """The model or table behind ``brdf``: a string ending in ``.json`` is a fit report,
        one naming an existing file or ending in a table format's extension a table (so a
        missing file is reported as missing), anything else a spec."""
        from ..models.base import Model
        from ..table import Table
        b = self.brdf
        if isinstance(b, (Model, Table)):
            return b
        if isinstance(b, str):
            from ..spec import parse
            if names_file(b) and b.lower().endswith(".json"):
                from ..fitting import load_report
                return load_report(b).model
            if names_file(b):
                from ..io import read
                return read(b)
            return parse(b)
        raise InputError(f"material: expected a model, spec, report or table, got {b!r}")


def names_file(text):
    """Whether the material string ``text`` names a file rather than a spec: it exists, or it
    ends in ``.json`` or a table format's extension, with no parenthesis."""
    import os
    from pathlib import Path
    from ..io import formats
    if "(" in text:
        return False
    suffix = Path(text).suffix.lower()
    return os.path.exists(text) or suffix == ".json" or any(
        suffix in m.EXTENSIONS for m in formats().values())


# --- shapes -----------------------------------------------------------------------------------

#: ``label``, a field of every shape and light: what error messages call it (a scene file's
#: ``shapes[2]``); by default ``shape K`` or ``light K`` after its place in the scene.
_LABEL = {"default": None, "compare": False, "repr": False}


@dataclass
class Sphere:
    centre: tuple
    radius: float
    material: object = None
    emission: object = None
    sides: str = "front"
    label: str = field(**_LABEL)


@dataclass
class Quad:
    """The parallelogram ``corner + a edge1 + b edge2`` (a, b in [0, 1]); its front faces
    edge1 x edge2; texture coordinates (a, b)."""

    corner: tuple
    edge1: tuple
    edge2: tuple
    material: object = None
    emission: object = None
    sides: str = "front"
    label: str = field(**_LABEL)


#: Mesh files :meth:`Mesh.read` takes (pyvista's surface readers).
MESH_EXTENSIONS = (".ply", ".obj", ".stl", ".vtk", ".vtp")
#: Largest mesh file read: 2 GB, some 40 million triangles in binary PLY.
MESH_BYTES = 2 << 30


@dataclass
class Mesh:
    """Triangles ``faces (m, 3)`` into ``vertices (n, 3)``, optional per-vertex ``normals`` and
    ``uv``."""

    vertices: np.ndarray
    faces: np.ndarray
    material: object = None
    normals: np.ndarray = None
    uv: np.ndarray = None
    label: str = field(**_LABEL)

    @classmethod
    def read(cls, path, material=None, transform=None):
        """A PLY, OBJ, STL or VTK mesh through pyvista (triangulated); ``transform`` a 4 x 4
        matrix applied to it."""
        import os
        import warnings
        from pathlib import Path
        from ..io.files import check_file
        suffix = Path(path).suffix.lower()
        if suffix not in MESH_EXTENSIONS:
            raise InputError(f"{path}: expected a mesh file ({', '.join(MESH_EXTENSIONS)}), "
                             f"got {suffix or 'no extension'}")
        if not os.path.exists(path):
            raise InputError(f"{path}: no such mesh file")
        check_file(path, MESH_BYTES, "a mesh file")
        T = None if transform is None else _floats(transform)
        if transform is not None and (T is None or T.shape != (16,) or not np.isfinite(T).all()):
            raise InputError(f"{path}: to_world: expected a 4 x 4 matrix of finite numbers")
        with warnings.catch_warnings():
            # pyvista announces future changes of its API on every read; not the user's concern
            warnings.simplefilter("ignore")
            import pyvista as pv
            try:
                mesh = pv.read(path).extract_surface().triangulate()
            except Exception as e:  # pyvista raises various types for unreadable files
                raise InputError(f"{path}: cannot read a mesh ({' '.join(str(e).split())})") \
                    from None
            if mesh.n_cells == 0:
                raise InputError(f"{path}: holds no triangles")
            if T is not None:
                mesh = mesh.transform(T.reshape(4, 4), inplace=False)
            faces = mesh.faces.reshape(-1, 4)[:, 1:]
            uv = mesh.active_texture_coordinates
            normals = mesh.point_data.get("Normals")
        return cls(np.asarray(mesh.points, float), faces, material,
                   None if normals is None else np.asarray(normals, float),
                   None if uv is None else np.asarray(uv, float))


def rectangle(to_world, material=None, emission=None, sides="front", label=None):
    """Mitsuba 3's ``rectangle``: the square [-1, 1]^2 at z = 0 facing +z, mapped by the 4 x 4
    matrix ``to_world``."""
    T = np.asarray(to_world, dtype=float)
    p = lambda x, y: T[:3, :3] @ [x, y, 0.0] + T[:3, 3]  # noqa: E731
    c = p(-1, -1)
    return Quad(c, p(1, -1) - c, p(-1, 1) - c, material, emission, sides, label)


def box(to_world, material=None, label=None):
    """Mitsuba 3's ``cube``: the six outward-facing faces of [-1, 1]^3 mapped by ``to_world``."""
    T = np.asarray(to_world, dtype=float)
    p = lambda v: T[:3, :3] @ v + T[:3, 3]  # noqa: E731
    faces = []
    for axis in range(3):
        for sign in (-1.0, 1.0):
            a, b = (axis + 1) % 3, (axis + 2) % 3
            if sign < 0:
                a, b = b, a  # keep edge1 x edge2 pointing outwards
            c = np.zeros(3)
            c[axis] = sign
            c[a] = c[b] = -1.0
            e1 = np.zeros(3)
            e1[a] = 2.0
            e2 = np.zeros(3)
            e2[b] = 2.0
            o = p(c)
            faces.append(Quad(o, p(c + e1) - o, p(c + e2) - o, material, label=label))
    return faces


# --- lights -----------------------------------------------------------------------------------

@dataclass
class PointLight:
    """Isotropic point light of intensity I (W/sr); irradiance I cos / (a r^2 + b r + c)."""

    position: tuple
    intensity: object = 1.0
    attenuation: tuple = (1.0, 0.0, 0.0)
    label: str = field(**_LABEL)


@dataclass
class SpotLight:
    """Point light emitting I cos^n(angle to ``direction``) inside a cone of half-angle
    ``cutoff`` degrees (n = ``exponent``, 2 by default)."""

    position: tuple
    direction: tuple
    intensity: object = 1.0
    cutoff: float = 30.0
    exponent: float = 2.0
    attenuation: tuple = (1.0, 0.0, 0.0)
    label: str = field(**_LABEL)


@dataclass
class DirectionalLight:
    """Parallel light travelling along ``direction`` with irradiance E (W/m^2) normal to it."""

    direction: tuple
    irradiance: object = 1.0
    label: str = field(**_LABEL)


@dataclass
class GoniometricLight:
    """Point light whose intensity is ``intensity`` times a table over direction: ``table``
    ``(len(theta), len(phi))`` at ``theta`` degrees from ``axis`` (0 to 180) and ``phi``
    degrees about it from ``phi_axis``; read one from an IES file with :meth:`from_ies`."""

    position: tuple
    table: np.ndarray
    theta: np.ndarray
    phi: np.ndarray
    intensity: object = 1.0
    axis: tuple = (0.0, -1.0, 0.0)
    phi_axis: tuple = (1.0, 0.0, 0.0)
    attenuation: tuple = (1.0, 0.0, 0.0)
    label: str = field(**_LABEL)

    @classmethod
    def from_ies(cls, path, position, **options):
        """A light from an IES LM-63 file (see :func:`~brdf.render.ies.read_ies`), ``axis``
        its nadir and ``phi_axis`` its horizontal angle 0."""
        from .ies import read_ies
        table, theta, phi = read_ies(path)
        # LM-63 turns horizontal angles counterclockwise seen from above, i.e. about the
        # zenith; this light turns phi about ``axis``, the nadir: phi = 360 - C
        return cls(position, table[:, ::-1], theta, 360.0 - phi[::-1], **options)

    def resampled(self):
        """The table on the kernel's regular (theta, phi) grid, bilinear and periodic in phi."""
        th = np.asarray(self.theta, float)
        ph = np.asarray(self.phi, float)
        tab = np.asarray(self.table, float)
        if tab.shape != (th.size, ph.size) or np.any(~np.isfinite(tab)) or np.any(tab < 0):
            raise InputError("goniometric table: expected non-negative finite values shaped "
                             "(len(theta), len(phi))")
        if np.any(np.diff(th) <= 0) or (ph.size > 1 and np.any(np.diff(ph) <= 0)):
            raise InputError("goniometric table: theta and phi must increase")
        gt = np.linspace(0.0, 180.0, L.GONIO_THETA)
        gp = np.linspace(0.0, 360.0, L.GONIO_PHI)
        # along theta: linear, held constant past the table's ends
        by_theta = np.stack([np.interp(gt, th, tab[:, j]) for j in range(ph.size)], axis=1)
        if ph.size == 1:
            return np.repeat(by_theta, L.GONIO_PHI, axis=1)
        period = np.concatenate([ph, [ph[0] + 360.0]])
        vals = np.concatenate([by_theta, by_theta[:, :1]], axis=1)
        return np.stack([np.interp(gp, period, row, period=360.0) for row in vals], axis=0)


@dataclass
class Environment:
    """Light from infinitely far away: constant ``radiance``, or ``radiance`` times an
    equirectangular map (an EXR/PNG path or an array (h, w, 3)) in Mitsuba 3's envmap layout
    with its +y axis along ``up``."""

    radiance: object = 1.0
    map: object = None
    up: tuple = (0.0, 1.0, 0.0)


# --- the scene --------------------------------------------------------------------------------

_SIDES = {"front": L.FRONT, "back": L.BACK, "both": L.FRONT | L.BACK}


class Compiled:
    """The kernels' view of a scene: ``geo``, ``mats`` and ``lights``, the named tuples of
    arrays declared beside the kernels that read them (``_intersect.Geometry``,
    ``_materials.Materials``, ``_lights.Lights``), and ``shape_of``, the index in
    ``Scene.shapes`` of each primitive (row of ``geo.prim``)."""

    def __init__(self, geo, mats, lights, bounds, shape_of=None, materials=None, extra=()):
        self.geo, self.mats, self.lights, self.bounds = geo, mats, lights, bounds
        self.shape_of = shape_of
        self._materials = materials or {}
        #: the rows of ``mats`` of :meth:`Scene.compile`'s ``extra`` materials
        self.extra = list(extra)

    def material_index(self, material):
        """The row of ``mats`` that holds ``material``, the object (or spec) some shape
        names, or None."""
        return self._materials.get(material if isinstance(material, str) else id(material))


@dataclass
class Scene:
    """Camera, shapes, lights and an optional environment.

    Shapes take a ``material`` (a :class:`Material`, model, spec, report path or table; None
    for a black surface) and an optional ``emission`` (radiance, making the shape an area
    light; quads and spheres only).
    """

    camera: Camera = field(default_factory=Camera)
    shapes: list = field(default_factory=list)
    lights: list = field(default_factory=list)
    environment: Environment = None
    #: the file the scene was read from (:func:`~brdf.render.scenes.load`), named first in
    #: the errors of :meth:`compile`
    source: str = field(default=None, compare=False)

    # -- compilation -----------------------------------------------------------------------------
    def compile(self, extra=()):
        """The :class:`Compiled` arrays, with the materials ``extra`` packed after the shapes'
        (no shape shows them; the derivative images evaluate f with one);
        :class:`InputError` for a shape, light or material that does not make sense, naming it
        (and the scene's file)."""
        try:
            return self._compile(extra)
        except InputError as e:
            if self.source:
                raise InputError(f"{self.source}: {e}") from None
            raise

    def _compile(self, extra):
        mats = _MaterialTable()
        material = np.array([mats.index(s.material) for s in self.shapes], dtype=np.int64)
        g = _geometry(self.shapes)
        prim = g.prim.copy()
        prim[:, 2] = material[g.shape_of]
        sph, quad = g.sph, g.quad
        scale = _scale(g.bounds)
        geo = X.Geometry(prim, sph, quad, g.tri, g.tri_n, g.tri_uv, *g.tree[:3], g.planes,
                         *g.tree[3:])
        # area lights from emissive shapes (meshes do not emit), in the primitives' order
        emitters = []
        for k, (i, count) in enumerate(zip(g.first, g.count)):
            s = self.shapes[k]
            if getattr(s, "emission", None) is None or not count:
                continue
            kind, j = prim[i, 0], prim[i, 1]
            if kind == X.TRIANGLE:
                raise InputError(f"{_label(s, k)}: emission is for quads and spheres")
            if not isinstance(s.sides, str) or s.sides not in _SIDES:
                raise InputError(f"{_label(s, k)}: sides must be front, back or both, got "
                                 f"{s.sides!r}")
            area = (4 * math.pi * sph[j, 3] ** 2 if kind == X.SPHERE
                    else float(np.linalg.norm(np.cross(quad[j, 1], quad[j, 2]))))
            f = np.zeros(16)
            f[0], f[1], f[2] = i, _SIDES[s.sides], area
            f[3:6] = rgb_value(s.emission, f"{_label(s, k)} emission")
            prim[i, 3] = len(emitters)
            emitters.append((L.AREA, f, area * math.pi * f[3:6].mean()))
        lights = _pack_lights(self, emitters, scale)
        shown = dict(mats.keys)
        extra = [mats.index(m) for m in extra]
        return Compiled(geo, mats.pack(), lights, tuple(g.bounds), g.shape_of, shown, extra)


#: What a scene's shapes compile to without their materials (:func:`_geometry`): the
#: primitives (``prim`` with materials and lights -1), each primitive's shape (``shape_of``),
#: each shape's first primitive and count (``first``, ``count``), the kinds' arrays, the
#: primitives' boxes (``lo``, ``hi``) and the scene's (``bounds``), the intersection planes and
#: the tree (:func:`_tree`'s six arrays).
_Shapes = namedtuple("_Shapes", "prim shape_of first count sph quad tri tri_n tri_uv lo hi "
                                "bounds planes tree")
class _Recent:
    """The last few values made, by key: at most ``kept`` of them and, with ``size`` (a value's
    bytes), at most ``limit`` bytes in all (the newest is kept whatever its size); the oldest
    used is let go first. Threads may share it."""

    def __init__(self, kept, limit=None, size=None):
        self.kept, self.limit, self.size = kept, limit, size
        self._values = OrderedDict()
        self._lock = threading.Lock()

    def __len__(self):
        return len(self._values)

    def get(self, key, make):
        """The value kept for ``key``, else ``make()``, kept unless ``key`` is None."""
        with self._lock:
            if key in self._values:
                self._values.move_to_end(key)
                return self._values[key]
        value = make()
        if key is not None:
            with self._lock:
                self._values[key] = value
                while len(self._values) > 1 and (len(self._values) > self.kept or (
                        self.limit is not None
                        and sum(map(self.size, self._values.values())) > self.limit)):
                    self._values.popitem(last=False)
        return value


def _geometry(shapes):
    """The :data:`_Shapes` of ``shapes``, their arrays read-only. A scene compiles on every
    render, and an inverse method renders the same shapes with other materials pass after
    pass: the 40,400-triangle mesh of ``bench_render.py`` took 36 ms a compile, mostly in
    numpy's passes over its triangles (their rows, boxes and planes). So the last few are kept
    (:data:`_GEOMETRIES`), by a digest of what the shapes hold (a shape whose values are not
    plain numbers is built again, and refused with its error)."""
    return _GEOMETRIES.get(_shapes_key(shapes), lambda: _read_only(_build_geometry(shapes)))


def _read_only(g):
    """:data:`_Shapes` ``g``, its arrays made read-only: the scenes that hold these shapes
    share them."""
    for a in _arrays(g):
        a.flags.writeable = False
    return g


def _arrays(g):
    """The arrays of :data:`_Shapes` ``g``."""
    return (*g[:-1], *g.tree)


#: The geometry of the last few scenes compiled (:func:`_geometry`): at most 4 of them and
#: 512 MiB in all.
_GEOMETRIES = _Recent(4, 1 << 29, lambda g: sum(a.nbytes for a in _arrays(g)))


#: what :func:`_shapes_key` reads of each kind of shape
_GEOMETRY_FIELDS = {Sphere: ("centre", "radius"), Quad: ("corner", "edge1", "edge2"),
                    Mesh: ("vertices", "faces", "normals", "uv")}


def _shapes_key(shapes):
    """A digest of the kinds and geometric values of ``shapes`` (not their materials, lights
    or labels), or None if one holds something other than numbers."""
    h = hashlib.sha256()
    for s in shapes:
        fields = _GEOMETRY_FIELDS.get(type(s))
        if fields is None:
            return None
        h.update(type(s).__name__.encode())
        for name in fields:
            value = getattr(s, name)
            if value is None:
                h.update(b"\0None")
                continue
            try:
                a = np.asarray(value)
            except (TypeError, ValueError):
                return None
            if a.dtype.kind not in "biuf":
                return None
            h.update(f"\0{a.dtype.str}{a.shape}".encode())
            h.update(np.ascontiguousarray(a))  # its buffer: no copy of a large mesh
    return h.digest()


def _build_geometry(shapes):
    """The :data:`_Shapes` of ``shapes``; :class:`InputError` for a shape that does not make
    sense, naming it."""
    # the primitives, a block of rows (kind, row in its kind's array, material, shape) per
    # shape: a mesh's triangles in one block, not a Python tuple each
    blocks = []
    sph, quad, tri, tri_n, tri_uv = [], [], [], [], []
    ntri = 0
    for k, s in enumerate(shapes):
        if isinstance(s, Sphere):
            r = _number(s.radius, f"{_label(s, k)} (sphere) radius")
            if not r > 0:
                raise InputError(f"{_label(s, k)} (sphere): radius must be positive, got "
                                 f"{s.radius}")
            sph.append(np.concatenate([_vec(s.centre, f"{_label(s, k)} centre"), [r]]))
            blocks.append(np.array([[X.SPHERE, len(sph) - 1, -1, k]], dtype=np.int64))
        elif isinstance(s, Quad):
            quad.append(quad_row(s, k))
            blocks.append(np.array([[X.QUAD, len(quad) - 1, -1, k]], dtype=np.int64))
        elif isinstance(s, Mesh):
            rows = _mesh_rows(s, k, tri, tri_n, tri_uv)
            block = np.empty((len(rows), 4), dtype=np.int64)
            block[:, 0], block[:, 1] = X.TRIANGLE, ntri + rows
            block[:, 2], block[:, 3] = -1, k
            ntri += len(rows)
            blocks.append(block)
        else:
            raise InputError(f"shape {k}: expected Sphere, Quad or Mesh, got "
                             f"{type(s).__name__}")
    prim = np.concatenate(blocks) if blocks else np.empty((0, 4), dtype=np.int64)
    if not len(prim):
        raise InputError("scene: no shapes")
    shape_of = prim[:, 3].copy()
    prim[:, 3] = -1
    count = np.array([len(b) for b in blocks], dtype=np.int64)
    first = np.cumsum(count) - count
    sph = np.array(sph, float).reshape(-1, 4)
    quad = np.array(quad, float).reshape(-1, 7, 3)
    tri = np.concatenate(tri).reshape(-1, 3, 3) if tri else np.empty((0, 3, 3))
    tri_n = np.concatenate(tri_n).reshape(-1, 3, 3) if tri_n else np.empty((0, 3, 3))
    tri_uv = np.concatenate(tri_uv).reshape(-1, 3, 2) if tri_uv else np.empty((0, 3, 2))
    lo, hi = _bounds(prim[:, 0], prim[:, 1], sph, quad, tri)
    bounds = np.stack([lo.min(axis=0), hi.max(axis=0)])
    pad = 1e-9 * (1.0 + _scale(bounds))
    tree = _tree(lo - pad, hi + pad)
    planes = _planes(prim, tree[2], quad, tri)
    return _Shapes(prim, shape_of, first, count, sph, quad, tri, tri_n, tri_uv, lo, hi, bounds,
                   planes, tree)


def _scale(bounds):
    """The largest magnitude of a coordinate in the scene's ``bounds`` (lower and upper
    corners): the largest of any primitive's box, as every box lies between them."""
    return float(np.max(np.abs(bounds)))


def _tree(lo, hi):
    """The BVH over boxes ``lo, hi`` with its leaves in blocks (:func:`.bvh.build_bvh`,
    :func:`.bvh.block_leaves`) and its wide form (:func:`.bvh.collapse`): ``(nodes, child,
    slots, wbox, wchild, entry)``; kept with the rest of the shapes' arrays (:func:`_geometry`):
    a mesh's SAH build took 0.15 s for 40,400 triangles."""
    nodes, child, order = build_bvh(lo, hi)
    child, slots = block_leaves(child, order)
    return (nodes, child, slots) + collapse(nodes, child)


def _label(item, k, kind="shape"):
    """What messages call shape (or light) ``k``: its ``label``, else ``shape K``."""
    return getattr(item, "label", None) or f"{kind} {k}"


def quad_row(s, k):
    """The packed row of quad ``s`` (shape ``k`` of its scene): corner, edges, normal and
    what the hit test needs (see the layout in ``_intersect``)."""
    where = _label(s, k)
    c, e1, e2 = (_vec(s.corner, f"{where} corner"), _vec(s.edge1, f"{where} edge1"),
                 _vec(s.edge2, f"{where} edge2"))
    if not np.linalg.norm(np.cross(e1, e2)) > 0:
        raise InputError(f"{where} (quad): edges are parallel (or too long)")
    n, q1, q2 = _plane_frame(e1[None], e2[None])
    return np.stack([c, e1, e2, n[0], q1[0], q2[0], e1 / np.linalg.norm(e1)])


def _plane_frame(e1, e2):
    """Unit normals n = e1 x e2 / |e1 x e2| and the dual vectors q1, q2 of the planes spanned
    by rows of ``e1, e2 (m, 3)``: (x - p) . q1 = a and (x - p) . q2 = b for x = p + a e1 + b e2."""
    n = np.cross(e1, e2)
    n /= np.linalg.norm(n, axis=1)[:, None]
    d1, d2 = np.cross(e2, n), np.cross(n, e1)
    return n, d1 / np.sum(e1 * d1, axis=1)[:, None], d2 / np.sum(e2 * d2, axis=1)[:, None]


def _mesh_rows(s, k, tri, tri_n, tri_uv):
    """Append mesh ``s``'s triangles (vertices, vertex normals, uv; its degenerate ones
    dropped) to the lists of blocks ``tri``, ``tri_n``, ``tri_uv``; returns their rows within
    the mesh's block, ``arange(count)``."""
    v = np.asarray(s.vertices, float)
    f = np.asarray(s.faces, dtype=np.int64)
    if v.ndim != 2 or v.shape[1] != 3 or f.ndim != 2 or f.shape[1] != 3:
        raise InputError(f"{_label(s, k)} (mesh): expected vertices (n, 3) and faces (m, 3)")
    if f.size and (f.min() < 0 or f.max() >= len(v)):
        raise InputError(f"{_label(s, k)} (mesh): face indices outside 0..{len(v) - 1}")
    tris = v[f]
    e = np.cross(tris[:, 1] - tris[:, 0], tris[:, 2] - tris[:, 0])
    keep = np.linalg.norm(e, axis=1) > 0  # degenerate triangles have no normal
    tri.append(tris[keep])
    nrm = np.zeros_like(tris) if s.normals is None else np.asarray(s.normals, float)[f]
    tri_n.append(nrm[keep])
    uv = np.zeros(tris.shape[:2] + (2,)) if s.uv is None else np.asarray(s.uv, float)[f]
    tri_uv.append(uv[keep])
    return np.arange(int(keep.sum()), dtype=np.int64)


def _planes(prim, slots, quad, tri):
    """The intersection kernels' ``planes (nb, PLANE_ROWS, LANES)`` for the primitives in
    ``slots`` (-1: padding, all zeros): a parallelogram's normal, corner and dual vectors as
    :func:`quad_row` has them; a triangle's with e1 = v1 - v0 and e2 = v2 - v0."""
    planes = np.zeros((X.PLANE_ROWS, len(slots)))
    ptype = np.where(slots >= 0, prim[slots, 0], -1)
    pidx = prim[slots, 1]
    q = ptype == X.QUAD
    r = quad[pidx[q]]
    planes[X.PN:X.PN + 3, q], planes[X.PP:X.PP + 3, q] = r[:, 3].T, r[:, 0].T
    planes[X.PQ1:X.PQ1 + 3, q], planes[X.PQ2:X.PQ2 + 3, q] = r[:, 4].T, r[:, 5].T
    t = ptype == X.TRIANGLE
    v = tri[pidx[t]]
    # degenerate triangles were dropped on reading
    n, q1, q2 = _plane_frame(v[:, 1] - v[:, 0], v[:, 2] - v[:, 0])
    planes[X.PN:X.PN + 3, t], planes[X.PP:X.PP + 3, t] = n.T, v[:, 0].T
    planes[X.PQ1:X.PQ1 + 3, t], planes[X.PQ2:X.PQ2 + 3, t] = q1.T, q2.T
    planes[X.PTRI, t] = 1.0
    planes[X.PSPH, ptype == X.SPHERE] = 1.0
    return np.ascontiguousarray(planes.reshape(X.PLANE_ROWS, -1, X.LANES).transpose(1, 0, 2))


def _bounds(ptype, pidx, sph, quad, tri):
    lo = np.empty((len(ptype), 3))
    hi = np.empty((len(ptype), 3))
    for kind, rows in ((X.SPHERE, sph), (X.QUAD, quad), (X.TRIANGLE, tri)):
        sel = ptype == kind
        if not sel.any():
            continue
        r = rows[pidx[sel]]
        if kind == X.SPHERE:
            lo[sel], hi[sel] = r[:, :3] - r[:, 3:], r[:, :3] + r[:, 3:]
        elif kind == X.QUAD:
            corners = np.stack([r[:, 0], r[:, 0] + r[:, 1], r[:, 0] + r[:, 2],
                                r[:, 0] + r[:, 1] + r[:, 2]], axis=1)
            lo[sel], hi[sel] = corners.min(axis=1), corners.max(axis=1)
        else:
            lo[sel], hi[sel] = r.min(axis=1), r.max(axis=1)
    return lo, hi


def _pack_lights(scene, emitters, scale):
    rows, gonio = list(emitters), []
    for k, light in enumerate(scene.lights):
        f = np.zeros(16)
        where = f"{_label(light, k, 'light')} ({type(light).__name__})"
        if isinstance(light, (PointLight, SpotLight, GoniometricLight)):
            f[0:3] = _vec(light.position, where + " position")
            f[3:6] = rgb_value(light.intensity, where + " intensity")
            att = _vec(light.attenuation, where + " attenuation")
            if np.any(att < 0) or not att.any():
                raise InputError(f"{where}: attenuation (a, b, c) must be non-negative, not all 0")
            f[6:9] = att
            power = 4 * math.pi * f[3:6].mean()
            kind = L.POINT
            if isinstance(light, SpotLight):
                kind = L.SPOT
                f[9:12] = _unit(light.direction, where + " direction")
                cutoff = _number(light.cutoff, where + " cutoff")
                exponent = _number(light.exponent, where + " exponent")
                if not 0 < cutoff <= 180:
                    raise InputError(f"{where}: cutoff must be in (0, 180] degrees")
                if not exponent >= 0:
                    raise InputError(f"{where}: exponent must be >= 0")
                f[12] = math.cos(math.radians(cutoff))
                f[13] = exponent
            elif isinstance(light, GoniometricLight):
                kind = L.GONIO
                a = _unit(light.axis, where + " axis")
                b = np.asarray(light.phi_axis, float)
                b = b - (b @ a) * a
                if np.linalg.norm(b) < 1e-9:
                    raise InputError(f"{where}: phi_axis must not be parallel to axis")
                f[9:12], f[12:15], f[15] = a, b / np.linalg.norm(b), len(gonio)
                gonio.append(light.resampled())
                power *= float(np.mean(gonio[-1]))
            rows.append((kind, f, power))
        elif isinstance(light, DirectionalLight):
            f[0:3] = _unit(light.direction, where + " direction")
            f[3:6] = rgb_value(light.irradiance, where + " irradiance")
            rows.append((L.DIRECTIONAL, f, math.pi * scale * scale * f[3:6].mean()))
        else:
            raise InputError(f"{where}: not a light")
    env, env_pmf = np.zeros((1, 1, 3)), np.ones((1, 1))
    env_prob, env_alias = np.ones(1), np.zeros(1, np.int64)
    env_cos, env_edge = np.zeros(2), np.zeros((2, 2))
    env_light = -1
    if scene.environment is not None:
        e = scene.environment
        f = np.zeros(16)
        f[3:6] = rgb_value(e.radiance, "environment radiance")
        mean = f[3:6].mean()
        if e.map is not None:
            from .image import read_image
            env = read_image(e.map, "environment map", channels=3)
            env_pmf = _env_distribution(env)
            env_prob, env_alias = L.alias_table(env_pmf.ravel())
            env_cos, env_edge = _env_edges(env)
            f[6:15] = _env_frame(e.up).ravel()
            f[0] = 1.0
            mean *= float(env.mean())
        env_light = len(rows)
        rows.append((L.ENV, f, 4 * math.pi * math.pi * scale * scale * mean))
    ltype = np.array([r[0] for r in rows], dtype=np.int64)
    lf = np.array([r[1] for r in rows], float).reshape(-1, 16)
    power = np.array([max(r[2], 0.0) for r in rows], float)
    # light selection in proportion to a power estimate, but never below a tenth of uniform,
    # so that a light the estimate undervalues (a spot, a small map) is still sampled
    pmf = power / power.sum() if power.sum() > 0 else np.full(len(rows), 1.0 / max(len(rows), 1))
    if len(rows):
        pmf = 0.9 * pmf + 0.1 / len(rows)
        pmf /= pmf.sum()
    gonio = (np.array(gonio, float) if gonio
             else np.zeros((1, L.GONIO_THETA, L.GONIO_PHI)))
    return L.Lights(ltype, lf, pmf, gonio, env, env_pmf, env_prob, env_alias, env_cos,
                    env_edge, env_light)


def _env_frame(up):
    """Rotation taking world directions into the map's frame, whose +y is ``up``."""
    y = _unit(up, "environment up")
    x = np.cross(y, [0.0, 0.0, 1.0]) if abs(y[2]) < 0.9 else np.cross(y, [1.0, 0.0, 0.0])
    if abs(y[1]) > 0.999999:
        x = np.array([1.0, 0.0, 0.0]) * np.sign(y[1])
    x /= np.linalg.norm(x)
    z = np.cross(x, y)
    return np.stack([x, y, z])


def _env_distribution(env):
    """Probabilities ``(h, w)`` of the map's pixels in proportion to sin(theta) times the
    largest luminance the bilinear radiance (``_lights._env_bilinear``) takes in the pixel
    (PBR 3rd ed. 14.2.4, with the bound in place of the pixel's value as pbrt-v4's
    ImageInfiniteLight samples its filtered image): wherever the radiance is not zero
    the density is not either, and it follows the radiance near bright pixels."""
    h, w, _ = env.shape
    lum = np.maximum(env @ np.array([0.2126, 0.7152, 0.0722]), 0.0)
    # in u the pixel's value spans its neighbours' halves (centres at (j + 1/2) / w) ...
    lum = np.maximum(np.maximum(lum, np.roll(lum, 1, axis=1)), np.roll(lum, -1, axis=1))
    # ... in v pixel row i spans theta / pi in [i / h, (i + 1) / h], between the map's rows
    # floor(i (h - 1) / h) and the two next (the radiance's rows sit at k / (h - 1))
    lo = (np.arange(h) * (h - 1)) // h
    lum = np.maximum(np.maximum(lum[lo], lum[np.minimum(lo + 1, h - 1)]),
                     lum[np.minimum(lo + 2, h - 1)])
    theta = (np.arange(h) + 0.5) / h * np.pi
    p = lum * np.sin(theta)[:, None]
    if p.sum() <= 0:
        p = np.sin(theta)[:, None] * np.ones((1, w))
    return p / p.sum()


def _env_edges(env):
    """The edges of the map's pixels: cos(pi i / h) of the rows' (h + 1) and the cos and sin of
    the columns' azimuths 2 pi j / w (w + 1, the last the first again)."""
    h, w, _ = env.shape
    a = 2.0 * np.pi * np.arange(w + 1) / w
    edge = np.stack([np.cos(a), np.sin(a)], axis=1)
    edge[-1] = edge[0]
    return np.cos(np.pi * np.arange(h + 1) / h), edge


def _named(material, i):
    """What messages call material ``i``: ``material 'NAME'`` or ``material I``."""
    name = getattr(material, "name", None)
    return f"material {name!r}" if name else f"material {i}"


class _MaterialTable:
    """Materials met while compiling shapes, deduplicated, packed into the ``mats`` tuple."""

    def __init__(self):
        self.items, self.keys = [], {}

    def index(self, material):
        if material is None:
            return -1
        key = id(material) if not isinstance(material, str) else material
        if key not in self.keys:
            self.keys[key] = len(self.items)
            self.items.append(material if isinstance(material, Material) else Material(material))
        return self.keys[key]

    def pack(self):
        from ..io.merl import MerlTable
        from ..models.base import Model
        rows, kinds, offs, params = [], [], [], []
        grids, filled, tables, bind, tex, texmeta = [], [], [], [], [], []
        shares = {}  # lobe layout -> the first material with it
        for i, mat in enumerate(self.items):
            b = mat.resolve()
            row = np.zeros(11, dtype=np.int64)
            row[[M.K0, M.O0, M.P0, M.B0]] = len(kinds), len(offs), len(params), len(bind)
            row[M.GRID] = -1
            if isinstance(b, Model) and not b.uses_kernels:
                b = _tabulated(b, i, mat)
            if isinstance(b, Model):
                if b.channels not in (1, 3):
                    raise InputError(f"{_named(mat, i)}: the renderer works in RGB; the model has "
                                     f"{b.channels} channels")
                c = b.compile(3)
                row[M.TYPE] = M.MODEL
                layout = (tuple(c.kinds), tuple(c.offsets))
                row[M.SHARE] = shares.setdefault(layout, i)
                _bind_textures(mat, b, c, i, bind, tex, texmeta)
                kinds.extend(c.kinds)
                offs.extend(c.offsets)
                params.extend(c.params)
            else:
                if mat.textures:
                    raise InputError(f"{_named(mat, i)}: textures apply to model parameters, not to "
                                     "measured tables")
                if b.channels != 3:
                    raise InputError(f"{_named(mat, i)}: the renderer works in RGB; the table has "
                                     f"{b.channels} channels")
                try:
                    t = b if isinstance(b, MerlTable) else MerlTable.from_table(b)
                except InputError as e:
                    raise InputError(f"{_named(mat, i)}: {e}") from None
                row[M.TYPE] = M.MEASURED
                row[M.SHARE] = i
                row[M.GRID] = len(grids)
                grids.append(np.asarray(t.grid, float))
                filled.append(np.asarray(t.filled, float))
                tables.append(M.tabulated(t))
            row[[M.K1, M.O1, M.P1, M.B1]] = len(kinds), len(offs), len(params), len(bind)
            rows.append(row)
        grid_shape = (1, 1, 1, 3)  # a placeholder the kernels never read
        return M.Materials(
            np.array(rows, np.int64).reshape(-1, 11),
            np.array(kinds, np.int64), np.array(offs, np.int64), np.array(params, float),
            _stacked(grids, (1,) + grid_shape), _stacked(filled, (1,) + grid_shape),
            _stacked(tables, (1, M.TAB_THETA_I, M.TAB_THETA * M.TAB_PHI + 1)),
            np.array(bind, np.int64).reshape(-1, 4),
            np.concatenate(tex) if tex else np.zeros(1),
            np.array(texmeta, np.int64).reshape(-1, 4))


def _stacked(arrays, empty):
    """``arrays`` stacked on a new first axis, a view of the one array if there is one (a MERL
    grid is 35 MB, and a scene is compiled at every render); zeros shaped ``empty`` if none."""
    if not arrays:
        return np.zeros(empty)
    return arrays[0][None] if len(arrays) == 1 else np.stack(arrays)


class _RGB:
    """A one-channel model seen as RGB (grey), for :meth:`MerlTable.from_table`."""

    channels = 3
    metadata = None

    def __init__(self, model):
        self.model, self.name = model, str(model)

    def eval(self, wi, wo):
        f = self.model.eval(wi, wo)
        return np.broadcast_to(f, f.shape[:-1] + (3,))

    def __str__(self):
        return self.name


def _tabulated(model, i, mat):
    """A model with custom (numpy) lobes, which have no kernels, tabulated on the MERL grid: the
    renderer then treats it as a measured table (trilinear lookups, tabulated sampling). The grid
    is isotropic and stores one value per reciprocal pair; sharp lobes lose detail below its
    resolution (1 degree in theta_d and phi_d, finer near the specular peak in theta_h)."""
    from ..io.merl import MerlTable
    if mat.textures:
        raise InputError(f"{_named(mat, i)}: {model} has custom lobes, which render through a "
                         "MERL-grid table, and textures apply to model parameters only")
    if model.is_anisotropic:
        raise InputError(f"{_named(mat, i)}: {model} is anisotropic (or its custom lobes do not "
                         "declare isotropic = True); the renderer tabulates custom lobes on the "
                         "isotropic MERL grid")
    if model.channels not in (1, 3):
        raise InputError(f"{_named(mat, i)}: the renderer works in RGB; the model has "
                         f"{model.channels} channels")
    # the families (classes: a family registered again is another) and the exact parameters
    key = (tuple(type(lobe) for lobe in model.lobes),
           json.dumps(model.to_dict(), sort_keys=True, default=repr))
    return _CUSTOM_TABLES.get(key, lambda: MerlTable.from_table(
        model if model.channels == 3 else _RGB(model)))


#: The tables of the last few custom-lobe models rendered (:func:`_tabulated`), by their
#: families and parameters: a scene compiles at every render, and evaluating a model's numpy
#: formula at the grid's 1.46 M nodes took 0.4-1.3 s of each. A table holds 35 MB (70 with its
#: filled copy), so two are kept.
_CUSTOM_TABLES = _Recent(2)


def _bind_textures(mat, model, compiled, i, bind, tex, texmeta):
    """Append texture bindings of material i: (material, slot, texture, channel) rows."""
    from ..models.base import Param
    from .image import read_image
    if not mat.textures:
        return
    names = model.lobe_names() if len(model.lobes) > 1 else [model.name]
    for flat, image in mat.textures.items():
        lobe_name, _, pname = str(flat).partition(".")
        if lobe_name not in names or not pname:
            raise InputError(f"{_named(mat, i)} texture {flat!r}: expected LOBE.PARAM with LOBE one "
                             f"of {', '.join(names)}")
        l = names.index(lobe_name)
        lobe = model.lobes[l]
        try:
            decl = lobe.declaration(pname)
        except Exception:
            decl = None
        if not isinstance(decl, Param):
            numeric = [d.name for d in lobe.PARAMS if isinstance(d, Param)]
            raise InputError(f"{_named(mat, i)} texture {flat!r}: not a numeric parameter of "
                             f"{lobe.name}; one of {', '.join(numeric)}")
        img = read_image(image, f"texture {flat}")
        lo, hi = decl.bounds
        img = np.clip(img, lo, hi)
        h, w, nc = img.shape
        texmeta.append((sum(t.size for t in tex), w, h, nc))
        tex.append(img.ravel())
        # a channel's texel value goes to every position of that channel's entry (all of a
        # scalar parameter's), those of a parameter falling back to it included
        for ch, positions in enumerate(compiled.slots[l][decl.name]):
            bind.extend((i, int(k), len(texmeta) - 1, ch) for k in positions)
