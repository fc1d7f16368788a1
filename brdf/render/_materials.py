"""Materials in the renderer: the library's own model kernels and measured MERL-layout grids.

A material is either a parametric model, evaluated, sampled and weighted by exactly the
kernels of :mod:`brdf.models._kernels` (no second copy of any formula), or a measured table on
the MERL grid, evaluated by :func:`brdf.io.merl.trilinear_at` and importance-sampled through a
tabulated distribution of f cos(theta) (see :func:`tabulate`).

Directions reach these kernels in the local shading frame. In the path tracer ``v`` is the
direction towards the viewer (the path's previous vertex) and ``l`` the one towards the light:
f is evaluated as f(wi = l, wo = v), the library's convention, and samples of ``l`` are drawn
given ``v`` (models sample their second argument given the first; for reciprocal models the
roles may be exchanged, and the one non-reciprocal family, the original Phong lobe, is then
re-evaluated in the right order).

The kernels take the materials as one :data:`Materials` tuple (built by
:meth:`brdf.render.scene.Scene.compile`): ``mint (nm, 11)`` one row per
material (columns below: type, measured grid, ranges into ``kinds``, ``offs``, ``params`` and
``bind``, and the first material with the same lobes and parameter layout, whose batch its
paths join: each path carries its own parameter row, so the Cornell box's three Lambertian
walls shade as one batch); the concatenated compiled models ``kinds``, ``offs`` (each
material's lobe offsets from 0) and ``params``; measured ``grids``, their gap-``filled``
copies and sampling ``tables``; texture bindings ``bind (nb, 4)`` (material, slot, texture,
channel) and the textures ``tex`` (flat) with ``texmeta (nt, 4)`` (offset, width, height,
channels).
"""

import math
import threading
import weakref
from collections import namedtuple

import numpy as np

from .._jit import OPTIMISED, allocating_kernel, inline_kernel, kernel, threaded_kernel
from ..io.merl import fetch_cell, trilinear_at
from ..models._kernels import (DRAW, DRAWN, GIVEN, PAIR, PDF, QUERY_ROWS, continuous,
                               cosine_over_pdf, mixture_batch)
from ..sampling import arccos, arctan2, sincos_turn, square_to_cosine_hemisphere

MODEL, MEASURED = 0, 1
#: columns of ``mint``
TYPE, GRID, K0, K1, O0, O1, P0, P1, SHARE, B0, B1 = range(11)
#: The materials as every kernel takes them (the arrays described above).
Materials = namedtuple("Materials", "mint kinds offs params grids filled tables bind tex texmeta")
#: Tabulated sampling of measured tables: incidence bins, theta_o cells, phi_o cells.
TAB_THETA_I, TAB_THETA, TAB_PHI = 24, 48, 96
#: cos(theta) at the theta_o cells' edges, i pi / (2 TAB_THETA) for i = 0 .. TAB_THETA (libm's
#: cosine, as the kernels' math.cos: two calls a density and a sample cost 3 % of a measured
#: material's render)
_EDGE_COS = np.array([math.cos(i * (0.5 * math.pi) / TAB_THETA) for i in range(TAB_THETA + 1)])
#: Share of cosine-weighted samples mixed into a measured table's tabulated sampling, so that
#: every direction the table reflects into has density (a defensive mixture; Hesterberg 1995).
DEFENSIVE = 0.2


# --- textures ---------------------------------------------------------------------------------

@inline_kernel
def wrapped_texels(x, n):
    """The texels either side of x in a periodic row of n texels with centres at 0 .. n - 1,
    for x in [-1/2, n - 1/2], and x's fraction past the first. floor(x) lies in [-1, n - 1], so
    they wrap with selects rather than an integer division (tens of cycles); the clamp keeps a
    NaN's index in range."""
    i = min(max(int(math.floor(x)), -1), n - 1)
    return (i if i >= 0 else n - 1), (i + 1 if i + 1 < n else 0), x - i


@inline_kernel
def texel_square(meta, t, u, v):
    """The four texels about (u, v) of texture t, wrapping (repeat), and their bilinear weights:
    the flat indices of their first channels (the left and right texel of the upper image row,
    then of the row below it) and the weights in that order. v = 0 is the image's bottom row,
    as in OpenGL and glTF's flipped convention of PNG rows."""
    off, w, h, nc = meta[t, 0], meta[t, 1], meta[t, 2], meta[t, 3]
    x = (u - math.floor(u)) * w - 0.5
    y = (1.0 - (v - math.floor(v))) * h - 0.5
    xa, xb, fx = wrapped_texels(x, w)
    ya, yb, fy = wrapped_texels(y, h)
    return (off + (ya * w + xa) * nc, off + (ya * w + xb) * nc, off + (yb * w + xa) * nc,
            off + (yb * w + xb) * nc, (1.0 - fx) * (1.0 - fy), fx * (1.0 - fy),
            (1.0 - fx) * fy, fx * fy)


@inline_kernel
def material_params(mats, m, u, v, row):
    """Write the packed parameters of material m at surface point (u, v) into ``row``: the
    material's own, with the slots that textures bind replaced by the textures' values there
    (bilinear; the channels a texture binds share its four texels' indices and weights)."""
    mint, bind, tex, meta = mats.mint, mats.bind, mats.tex, mats.texmeta
    p0 = mint[m, P0]
    for j in range(mint[m, P1] - p0):  # a slice assignment may allocate, which kernels cannot
        row[j] = mats.params[p0 + j]
    t = -1
    k00 = k01 = k10 = k11 = 0
    w00 = w01 = w10 = w11 = 0.0
    for j in range(mint[m, B0], mint[m, B1]):
        if bind[j, 2] != t:
            t = bind[j, 2]
            k00, k01, k10, k11, w00, w01, w10, w11 = texel_square(meta, t, u, v)
        c = min(bind[j, 3], meta[t, 3] - 1)
        row[bind[j, 1]] = (w00 * tex[k00 + c] + w01 * tex[k01 + c] + w10 * tex[k10 + c]
                           + w11 * tex[k11 + c])


# --- measured tables: tabulated importance sampling --------------------------------------------

@kernel(linked=OPTIMISED)
def _tab_bin(vz):
    """Incidence bin of cos(theta_v) = vz (bins uniform in theta)."""
    theta = arccos(max(vz, 0.0))
    return min(int(theta / (0.5 * math.pi) * TAB_THETA_I), TAB_THETA_I - 1)


@kernel(linked=OPTIMISED)
def _cell_solid_angle(i):
    return (_EDGE_COS[i] - _EDGE_COS[i + 1]) * (2.0 * math.pi / TAB_PHI)


@kernel(linked=OPTIMISED)
def _cell_density(row, c):
    """Density per solid angle of cell c of a bin's CDF ``row``: its probability over its solid
    angle."""
    return (row[c + 1] - row[c]) / _cell_solid_angle(c // TAB_PHI)


@kernel(linked=OPTIMISED)
def _defensive_mixture(tab, lz):
    """Density of the defensive mixture at l above the horizon (with v above it too): the
    tabulated part's density ``tab`` there, and cosine sampling's."""
    return (1.0 - DEFENSIVE) * tab + DEFENSIVE * lz / math.pi


@inline_kernel
def _tab_pdf(cdf, vx, vy, vz, lx, ly, lz):
    """Density of the tabulated part at l given v: cell probability over cell solid angle, in
    coordinates where phi is measured from v's azimuth (the table is isotropic)."""
    if lz <= 0.0:
        return 0.0
    b = _tab_bin(vz)
    # l's azimuth from v's in [0, 2 pi): one arctangent of the angle between their
    # projections; v at the pole has azimuth 0, as the sampler's atan2(0, 0) gives it
    if vx == 0.0 and vy == 0.0:
        phi = arctan2(ly, lx)
    else:
        phi = arctan2(vx * ly - vy * lx, vx * lx + vy * ly)
    phi = phi + 2.0 * math.pi if phi < 0.0 else phi
    it = min(int(arccos(lz) / (0.5 * math.pi) * TAB_THETA), TAB_THETA - 1)
    ip = min(int(phi / (2.0 * math.pi) * TAB_PHI), TAB_PHI - 1)
    return _cell_density(cdf[b], it * TAB_PHI + ip)


@inline_kernel
def _tab_sample(cdf, vx, vy, vz, u1, u2):
    """A cell by inverting the bin's CDF with u1 (then u1 rescaled within the cell), uniform in
    (cos theta, phi) within it: constant density per solid angle over the cell. Returns the
    direction and that density (what :func:`_tab_pdf` gives there, without finding the cell
    again)."""
    b = _tab_bin(vz)
    row = cdf[b]
    c = np.searchsorted(row, u1, side="right") - 1
    c = min(max(c, 0), TAB_THETA * TAB_PHI - 1)
    width = row[c + 1] - row[c]
    s = (u1 - row[c]) / width if width > 0.0 else 0.5
    s = min(max(s, 0.0), 1.0)
    it, ip = c // TAB_PHI, c % TAB_PHI
    c0, c1 = _EDGE_COS[it], _EDGE_COS[it + 1]
    z = c0 + (c1 - c0) * s
    # phi in turns: the cell's, from the azimuth of v
    sin_phi, cos_phi = sincos_turn((ip + u2) / TAB_PHI + arctan2(vy, vx) / (2.0 * math.pi))
    r = math.sqrt(max(0.0, 1.0 - z * z))
    return r * cos_phi, r * sin_phi, z, _cell_density(row, c)


@inline_kernel
def _measured_pdf(cdf, vx, vy, vz, lx, ly, lz):
    if lz <= 0.0 or vz <= 0.0:
        return 0.0
    return _defensive_mixture(_tab_pdf(cdf, vx, vy, vz, lx, ly, lz), lz)


# --- the material interface of the integrator -------------------------------------------------
#
# The integrator shades its paths in batches, the paths on one material at a time: item j reads
# its packed parameters from the row ``lp[j * step]`` (the material's, or a texel's where
# textures bind them; see :func:`material_params`; step 0: one row for every item) and its
# directions from the query sets ``q[s] (QUERY_ROWS, n)`` of
# :func:`brdf.models._kernels.mixture_batch`, in the local shading frame:
# v towards the viewer (rows GIVEN), l towards the light (rows DRAWN) and a density (row PDF).
# f is evaluated as f(wi = l, wo = v), and l is drawn given v.


@inline_kernel
def _measured_batch(grid, filled, cdf, q, f, u1, u2, lists, counts):
    """The passes of :func:`brdf.models._kernels.mixture_batch` for a measured table: f by
    trilinear lookup, l drawn by the tabulated distribution mixed with cosine sampling."""
    d = q[DRAW]
    for t in range(counts[1]):
        j = lists[1, t]
        a, b = u1[j], u2[j]
        vx, vy, vz = d[GIVEN, j], d[GIVEN + 1, j], d[GIVEN + 2, j]
        if a < DEFENSIVE:
            x, y, z = square_to_cosine_hemisphere(a / DEFENSIVE, b)
            pdf = _measured_pdf(cdf, vx, vy, vz, x, y, z)
        else:
            x, y, z, tab = _tab_sample(cdf, vx, vy, vz, (a - DEFENSIVE) / (1.0 - DEFENSIVE), b)
            # _measured_pdf, with the tabulated part's density known from the sample's cell
            pdf = _defensive_mixture(tab, z) if z > 0.0 and vz > 0.0 else 0.0
        d[DRAWN, j], d[DRAWN + 1, j], d[DRAWN + 2, j] = x, y, z
        d[PDF, j] = pdf
        for c in range(3):
            f[DRAW, j, c] = 0.0
    sampled = continuous(lists[1], counts[1], d[PDF], lists[4])
    pair = q[PAIR]
    for t in range(counts[3]):
        j = lists[3, t]
        pair[PDF, j] = _measured_pdf(cdf, pair[GIVEN, j], pair[GIVEN + 1, j], pair[GIVEN + 2, j],
                                     pair[DRAWN, j], pair[DRAWN + 1, j], pair[DRAWN + 2, j])
    # every lookup's cell fetched first (stage 0), then looked up (see fetch_cell); f holds a
    # lane's grid coordinates in between
    for stage in range(2):
        for s in (PAIR, DRAW):
            ev, nev = (lists[2], counts[2]) if s == PAIR else (lists[4], sampled)
            e = q[s]
            for t in range(nev):
                j = ev[t]
                above = e[DRAWN + 2, j] > 0.0 and e[GIVEN + 2, j] > 0.0
                if stage == 0:
                    if above:
                        fetch_cell(grid, e[DRAWN, j], e[DRAWN + 1, j], e[DRAWN + 2, j],
                                   e[GIVEN, j], e[GIVEN + 1, j], e[GIVEN + 2, j], f[s], j)
                elif above:
                    trilinear_at(grid, filled, f[s], j)
                else:
                    f[s, j, 0] = f[s, j, 1] = f[s, j, 2] = 0.0
    cosine_over_pdf(lists[4], sampled, d[DRAWN + 2], d[PDF], f[DRAW])


@inline_kernel
def bsdf_shade(mats, m, lp, step, q, f, u1, u2, sel, work, chosen, lists, counts):
    """Shade a batch of paths on material m (see
    :func:`brdf.models._kernels.mixture_batch` for the query sets and lists): draw l given v
    at ``lists[1]``, with its density and the weight f(l, v) cos / pdf in ``f[DRAW]``; f(l, v)
    at ``lists[2]`` and the density of l at ``lists[3]`` in set PAIR. ``lists[0]`` repeats
    ``lists[1]``, and ``lists[4]`` is work space. Item j's parameters are row ``j * step`` of
    ``lp`` (a measured table has none)."""
    mint = mats.mint
    if mint[m, TYPE] == MEASURED:
        g = mint[m, GRID]
        _measured_batch(mats.grids[g], mats.filled[g], mats.tables[g], q, f, u1, u2, lists, counts)
        return
    mixture_batch(mats.kinds[mint[m, K0]:mint[m, K1]], mats.offs[mint[m, O0]:mint[m, O1]], lp,
                  step, 3, q, f, u1, u2, sel, work, chosen, lists, counts, False)


def tabulate(table):
    """Per-incidence-bin CDFs ``(TAB_THETA_I, TAB_THETA * TAB_PHI + 1)`` of f cos(theta_l) times
    cell solid angle (channel mean) for an isotropic table, from 2 x 2 sub-cell samples per
    cell at each bin's centre incidence (azimuth 0)."""
    ti = (np.arange(TAB_THETA_I) + 0.5) * (0.5 * np.pi) / TAB_THETA_I
    sub = np.array([0.25, 0.75])
    th = (np.arange(TAB_THETA)[:, None] + sub[None, :]).ravel() * (0.5 * np.pi) / TAB_THETA
    ph = (np.arange(TAB_PHI)[:, None] + sub[None, :]).ravel() * (2.0 * np.pi) / TAB_PHI
    T, P = np.meshgrid(th, ph, indexing="ij")
    lo = np.stack([np.sin(T) * np.cos(P), np.sin(T) * np.sin(P), np.cos(T)], axis=-1)
    cdf = np.zeros((TAB_THETA_I, TAB_THETA * TAB_PHI + 1))
    edges = np.arange(TAB_THETA + 1) * (0.5 * np.pi) / TAB_THETA
    omega = (np.cos(edges[:-1]) - np.cos(edges[1:])) * (2.0 * np.pi / TAB_PHI)
    for b, t in enumerate(ti):
        v = np.broadcast_to([np.sin(t), 0.0, np.cos(t)], lo.shape)
        f = np.asarray(table.eval(lo, v)).mean(axis=-1) * lo[..., 2]
        f = np.nan_to_num(np.maximum(f, 0.0))
        cell = f.reshape(TAB_THETA, 2, TAB_PHI, 2).mean(axis=(1, 3)) * omega[:, None]
        total = cell.sum()
        w = cell.ravel() / total if total > 0 else np.full(cell.size, 1.0 / cell.size)
        cdf[b, 1:] = np.cumsum(w)
        cdf[b, -1] = 1.0
    return cdf


#: :func:`tabulate`'s CDFs of each read-only table still alive (a MerlTable never changes)
_TABULATED = weakref.WeakKeyDictionary()
_TABULATING = threading.Lock()


def tabulated(table):
    """:func:`tabulate` of a read-only MERL table, computed once for as long as the table lives:
    a scene is compiled at every render, and tabulating took 70 ms of a MERL scene's 0.7 s."""
    with _TABULATING:
        cdf = _TABULATED.get(table)
        if cdf is None:
            cdf = _TABULATED[table] = tabulate(table)
            cdf.setflags(write=False)
        return cdf


#: Directions per batch of the array drivers below.
BATCH = 256


@allocating_kernel
def _driver_space(mats, m, v, k0, count, lists, counts):
    """Work space of :func:`bsdf_shade` for the directions v[k0:k0 + count] on material m: query
    sets with v in rows GIVEN, values, the uniform pair, the material's parameter row (step 0),
    selection, work and chosen; the lists get the items in order."""
    mint, params = mats.mint, mats.params
    p = params[mint[m, P0]:mint[m, P1]]
    q, f, u = np.zeros((2, QUERY_ROWS, BATCH)), np.zeros((2, BATCH, 3)), np.zeros((2, BATCH))
    lp = np.zeros((1, max(p.shape[0], 1)))
    lp[0, :p.shape[0]] = p
    for t in range(count):
        for a in range(3):
            q[PAIR, GIVEN + a, t] = q[DRAW, GIVEN + a, t] = v[k0 + t, a]
        for k in range(4):
            lists[k, t] = t
    return (q, f, u, lp, np.zeros((BATCH, max(mint[m, K1] - mint[m, K0], 1))),
            np.zeros((BATCH, 2)), np.zeros(BATCH, np.int64))


@threaded_kernel("v", "u", "l", "pdf", "weight", align=BATCH)
def sample_array(mats, m, v, u, l, pdf, weight):
    """Array driver of :func:`bsdf_shade`'s draw for material m (tests, plots): l, pdf, weight
    for each view direction v[k] and uniform pair u[k]."""
    n = v.shape[0]
    for b in range((n + BATCH - 1) // BATCH):
        k0 = b * BATCH
        c = min(BATCH, n - k0)
        lists, counts = np.zeros((5, BATCH), np.int64), np.zeros(4, np.int64)
        q, f, uu, lp, sel, work, chosen = _driver_space(mats, m, v, k0, c, lists, counts)
        for t in range(c):
            uu[0, t], uu[1, t] = u[k0 + t, 0], u[k0 + t, 1]
        counts[0] = counts[1] = c
        bsdf_shade(mats, m, lp, 0, q, f, uu[0], uu[1], sel, work, chosen, lists, counts)
        for t in range(c):
            for a in range(3):
                l[k0 + t, a] = q[DRAW, DRAWN + a, t]
            pdf[k0 + t] = q[DRAW, PDF, t]
            for a in range(3):
                weight[k0 + t, a] = f[DRAW, t, a]


@threaded_kernel("v", "l", "pdf", align=BATCH)
def pdf_array(mats, m, v, l, pdf):
    """Array driver of :func:`bsdf_shade`'s density for material m."""
    n = v.shape[0]
    for b in range((n + BATCH - 1) // BATCH):
        k0 = b * BATCH
        c = min(BATCH, n - k0)
        lists, counts = np.zeros((5, BATCH), np.int64), np.zeros(4, np.int64)
        q, f, uu, lp, sel, work, chosen = _driver_space(mats, m, v, k0, c, lists, counts)
        for t in range(c):
            for a in range(3):
                q[PAIR, DRAWN + a, t] = l[k0 + t, a]
        counts[0] = counts[3] = c
        bsdf_shade(mats, m, lp, 0, q, f, uu[0], uu[1], sel, work, chosen, lists, counts)
        pdf[k0:k0 + c] = q[PAIR, PDF, :c]
