"""Materials in the renderer: the library's own model kernels and measured MERL-layout grids.

A material is either a parametric model, evaluated, sampled and weighted by exactly the
kernels of :mod:`brdf.models._kernels` (no second copy of any formula), or a measured table on
the MERL grid, evaluated by :func:`brdf.io.merl.trilinear_pair` and importance-sampled through a
tabulated distribution of f cos(theta) (see :func:`tabulate`).

Directions reach these kernels in the local shading frame. In the path tracer ``v`` is the
direction towards the viewer (the path's previous vertex) and ``l`` the one towards the light:
f is evaluated as f(wi = l, wo = v), the library's convention, and samples of ``l`` are drawn
given ``v`` (models sample their second argument given the first; for reciprocal models the
roles may be exchanged, and the one non-reciprocal family, the original Phong lobe, is then
re-evaluated in the right order).

Material arrays (see :class:`brdf.render.scene.Compiled`): ``mint (nm, 11)`` one row per
material (columns below: type, measured grid, ranges into ``kinds``, ``offs``, ``params`` and
``bind``, flags); the concatenated compiled models ``kinds``, ``offs`` (each material's lobe
offsets from 0) and ``params``; measured ``grids``, their gap-``filled`` copies and sampling
``tables``; texture bindings ``bind (nb, 4)`` (material, slot, texture, channel) and the
textures ``tex`` (flat) with ``texmeta (nt, 4)`` (offset, width, height, channels).
"""

import math

import numpy as np
from numba import prange

from .._jit import inline_kernel, kernel, parallel_kernel
from ..io.merl import trilinear_pair
from ..models._kernels import material_eval, material_pdf, material_sample
from ..sampling import square_to_cosine_hemisphere

MODEL, MEASURED = 0, 1
#: columns of ``mint``
TYPE, GRID, K0, K1, O0, O1, P0, P1, FLAGS, B0, B1 = range(11)
#: flags bit: the model is not reciprocal (evaluate f(l, v) explicitly after sampling)
NONRECIPROCAL = 1
#: Tabulated sampling of measured tables: incidence bins, theta_o cells, phi_o cells.
TAB_THETA_I, TAB_THETA, TAB_PHI = 24, 48, 96
#: Share of cosine-weighted samples mixed into a measured table's tabulated sampling, so that
#: every direction the table reflects into has density (a defensive mixture; Hesterberg 1995).
DEFENSIVE = 0.2


# --- textures ---------------------------------------------------------------------------------

@inline_kernel
def texture_lookup(tex, meta, t, ch, u, v):
    """Bilinear lookup of channel ``ch`` of texture ``t`` at (u, v), wrapping (repeat); v = 0 is
    the image's bottom row, as in OpenGL and glTF's flipped convention of PNG rows."""
    off, w, h, nc = meta[t, 0], meta[t, 1], meta[t, 2], meta[t, 3]
    x = (u - math.floor(u)) * w - 0.5
    y = (1.0 - (v - math.floor(v))) * h - 0.5
    x0 = int(math.floor(x))
    y0 = int(math.floor(y))
    fx, fy = x - x0, y - y0
    acc = 0.0
    for dy in range(2):
        yy = (y0 + dy) % h
        wy = fy if dy else 1.0 - fy
        for dx in range(2):
            xx = (x0 + dx) % w
            wx = fx if dx else 1.0 - fx
            acc += wx * wy * tex[off + (yy * w + xx) * nc + min(ch, nc - 1)]
    return acc


@inline_kernel
def material_params(mint, params, bind, tex, texmeta, m, u, v, scratch):
    """The packed parameters of material m at surface point (u, v): the material's own, or,
    where textures bind some of its slots, a copy in ``scratch`` with those slots replaced by
    the textures' values there."""
    p = params[mint[m, P0]:mint[m, P1]]
    if mint[m, B0] == mint[m, B1]:
        return p
    q = scratch[:p.shape[0]]
    for j in range(p.shape[0]):  # a slice assignment may allocate, which kernels cannot
        q[j] = p[j]
    for j in range(mint[m, B0], mint[m, B1]):
        q[bind[j, 1]] = texture_lookup(tex, texmeta, bind[j, 2], bind[j, 3], u, v)
    return q


# --- measured tables: tabulated importance sampling --------------------------------------------

@kernel
def _tab_bin(vz):
    """Incidence bin of cos(theta_v) = vz (bins uniform in theta)."""
    theta = math.acos(min(max(vz, 0.0), 1.0))
    return min(int(theta / (0.5 * math.pi) * TAB_THETA_I), TAB_THETA_I - 1)


@kernel
def _cell_solid_angle(i):
    t0 = i * (0.5 * math.pi) / TAB_THETA
    t1 = (i + 1) * (0.5 * math.pi) / TAB_THETA
    return (math.cos(t0) - math.cos(t1)) * (2.0 * math.pi / TAB_PHI)


@inline_kernel
def _tab_pdf(cdf, vx, vy, vz, lx, ly, lz):
    """Density of the tabulated part at l given v: cell probability over cell solid angle, in
    coordinates where phi is measured from v's azimuth (the table is isotropic)."""
    if lz <= 0.0:
        return 0.0
    b = _tab_bin(vz)
    phi = math.atan2(ly, lx) - math.atan2(vy, vx)
    phi = phi % (2.0 * math.pi)
    it = min(int(math.acos(min(lz, 1.0)) / (0.5 * math.pi) * TAB_THETA), TAB_THETA - 1)
    ip = min(int(phi / (2.0 * math.pi) * TAB_PHI), TAB_PHI - 1)
    c = it * TAB_PHI + ip
    return (cdf[b, c + 1] - cdf[b, c]) / _cell_solid_angle(it)


@inline_kernel
def _tab_sample(cdf, vx, vy, vz, u1, u2):
    """A cell by inverting the bin's CDF with u1 (then u1 rescaled within the cell), uniform in
    (cos theta, phi) within it: constant density per solid angle over the cell."""
    b = _tab_bin(vz)
    row = cdf[b]
    c = np.searchsorted(row, u1, side="right") - 1
    c = min(max(c, 0), TAB_THETA * TAB_PHI - 1)
    width = row[c + 1] - row[c]
    s = (u1 - row[c]) / width if width > 0.0 else 0.5
    s = min(max(s, 0.0), 1.0)
    it, ip = c // TAB_PHI, c % TAB_PHI
    c0 = math.cos(it * (0.5 * math.pi) / TAB_THETA)
    c1 = math.cos((it + 1) * (0.5 * math.pi) / TAB_THETA)
    z = c0 + (c1 - c0) * s
    phi = (ip + u2) * (2.0 * math.pi / TAB_PHI) + math.atan2(vy, vx)
    r = math.sqrt(max(0.0, 1.0 - z * z))
    return r * math.cos(phi), r * math.sin(phi), z


@inline_kernel
def _measured_pdf(cdf, vx, vy, vz, lx, ly, lz):
    if lz <= 0.0 or vz <= 0.0:
        return 0.0
    return (1.0 - DEFENSIVE) * _tab_pdf(cdf, vx, vy, vz, lx, ly, lz) + DEFENSIVE * lz / math.pi


# --- the material interface of the integrator -------------------------------------------------

@inline_kernel
def bsdf_eval(mint, kinds, offs, grids, filled, m, p, vx, vy, vz, lx, ly, lz, out):
    """f(wi = l, wo = v) into ``out[0, :3]`` (zeroed first)."""
    for c in range(3):
        out[0, c] = 0.0
    if mint[m, TYPE] == MEASURED:
        if lz > 0.0 and vz > 0.0:
            g = mint[m, GRID]
            trilinear_pair(grids[g], filled[g], lx, ly, lz, vx, vy, vz, out, 0)
        return
    material_eval(kinds[mint[m, K0]:mint[m, K1]], offs[mint[m, O0]:mint[m, O1]], p, 3,
                  lx, ly, lz, vx, vy, vz, out, 0)


@inline_kernel
def bsdf_pdf(mint, kinds, offs, tables, m, p, vx, vy, vz, lx, ly, lz):
    """Solid-angle density with which :func:`bsdf_sample` draws l given v."""
    if mint[m, TYPE] == MEASURED:
        return _measured_pdf(tables[mint[m, GRID]], vx, vy, vz, lx, ly, lz)
    return material_pdf(kinds[mint[m, K0]:mint[m, K1]], offs[mint[m, O0]:mint[m, O1]], p, 3,
                        vx, vy, vz, lx, ly, lz)


@inline_kernel
def bsdf_sample(mint, kinds, offs, grids, filled, tables, m, p, vx, vy, vz, u1, u2, weight):
    """Draw l given v: returns ``(lx, ly, lz, pdf)`` and writes f(l, v) cos(theta_l) / pdf into
    ``weight[0, :3]``; pdf is inf for a delta lobe, 0 for no sample."""
    if mint[m, TYPE] == MEASURED:
        cdf = tables[mint[m, GRID]]
        if u1 < DEFENSIVE:
            lx, ly, lz = square_to_cosine_hemisphere(u1 / DEFENSIVE, u2)
        else:
            lx, ly, lz = _tab_sample(cdf, vx, vy, vz, (u1 - DEFENSIVE) / (1.0 - DEFENSIVE), u2)
        pdf = _measured_pdf(cdf, vx, vy, vz, lx, ly, lz)
        if pdf <= 0.0:
            return lx, ly, lz, 0.0
        bsdf_eval(mint, kinds, offs, grids, filled, m, p, vx, vy, vz, lx, ly, lz, weight)
        for c in range(3):
            weight[0, c] *= lz / pdf
        return lx, ly, lz, pdf
    lx, ly, lz, pdf = material_sample(kinds[mint[m, K0]:mint[m, K1]],
                                      offs[mint[m, O0]:mint[m, O1]], p, 3, vx, vy, vz, u1, u2,
                                      weight, 0)
    if (mint[m, FLAGS] & NONRECIPROCAL) and pdf > 0.0 and pdf < math.inf:
        bsdf_eval(mint, kinds, offs, grids, filled, m, p, vx, vy, vz, lx, ly, lz, weight)
        for c in range(3):
            weight[0, c] *= lz / pdf
    return lx, ly, lz, pdf


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


@parallel_kernel
def sample_array(mats, m, v, u, l, pdf, weight):
    """Array driver of :func:`bsdf_sample` for material m (tests, plots): l, pdf, weight for
    each view direction v[k] and uniform pair u[k]."""
    mint, kinds, offs, params, grids, filled, tables, bind, tex, texmeta = mats
    p = params[mint[m, P0]:mint[m, P1]]
    for k in prange(v.shape[0]):
        w = np.zeros((1, 3))
        lx, ly, lz, pk = bsdf_sample(mint, kinds, offs, grids, filled, tables, m, p,
                                     v[k, 0], v[k, 1], v[k, 2], u[k, 0], u[k, 1], w)
        l[k, 0], l[k, 1], l[k, 2], pdf[k] = lx, ly, lz, pk
        weight[k, 0], weight[k, 1], weight[k, 2] = w[0, 0], w[0, 1], w[0, 2]


@parallel_kernel
def pdf_array(mats, m, v, l, pdf):
    """Array driver of :func:`bsdf_pdf` for material m."""
    mint, kinds, offs, params, grids, filled, tables, bind, tex, texmeta = mats
    p = params[mint[m, P0]:mint[m, P1]]
    for k in prange(v.shape[0]):
        pdf[k] = bsdf_pdf(mint, kinds, offs, tables, m, p, v[k, 0], v[k, 1], v[k, 2],
                          l[k, 0], l[k, 1], l[k, 2])
