"""A small radiosity solver: an independent answer for all-Lambertian quad scenes.

Written apart from the path tracer (numpy only, its own ray casting) so that the two can check
each other. Every quad of the scene is cut into ``patches x patches`` patches on each of its
two sides (the path tracer's surfaces reflect on both sides); the radiance of a patch is taken
constant over it and solves the discrete rendering equation (Goral et al. 1984, eq. 4; Cohen
and Wallace 1993, eq. 2.6, in radiance rather than radiosity B = pi L)::

    L_i = Le_i + rho_i sum_j F_ij L_j

by Jacobi iteration. The form factor F_ij from patch i to patch j is the mean over ``samples
x samples`` points x of patch i of the exact point-to-polygon form factor of patch j (Lambert's
contour formula, Cohen and Wallace 1993, eq. 4.10), times the share of rays from x to
``samples x samples`` points of j that no quad blocks (ray-cast visibility, Wallace et al.
1989). Where patch j crosses the plane of patch i, the formula is applied to the part of j in
front of that plane (clipped), and visibility is sampled towards the points of j there.
"""

import math
from dataclasses import dataclass

import numpy as np

from ..errors import InputError

__all__ = ["Radiosity", "solve"]


@dataclass
class Radiosity:
    """A solved radiosity mesh.

    Attributes
    ----------
    corner, edge1, edge2 : ndarray (n, 3)
        Each patch is ``corner + a edge1 + b edge2`` with a, b in [0, 1].
    normal : ndarray (n, 3)
        The unit normal of the side the patch stands for.
    quad, side : ndarray (n,)
        Index of the patch's shape in the scene, and +1 (front) or -1 (back).
    area : ndarray (n,)
    radiance : ndarray (n, 3)
        Outgoing radiance of each patch (emitted plus reflected), RGB.
    iterations : int
        Jacobi sweeps until the largest change fell below the tolerance.
    """

    corner: np.ndarray
    edge1: np.ndarray
    edge2: np.ndarray
    normal: np.ndarray
    quad: np.ndarray
    side: np.ndarray
    area: np.ndarray
    radiance: np.ndarray
    iterations: int
    patches: int
    _quads: tuple

    def image(self, camera, width, height):
        """Radiance seen through the centres of the pixels of ``camera`` (a
        :class:`~brdf.render.Camera`), ``(height, width, 3)``; 0 where no quad is hit."""
        cam = camera.pack(width, height)
        x = (np.arange(width) + 0.5) / width * 2.0 - 1.0
        y = 1.0 - (np.arange(height) + 0.5) / height * 2.0
        X, Y = np.meshgrid(x, y)
        d = cam[3:6] + X[..., None] * cam[6:9] + Y[..., None] * cam[9:12]
        d = (d / np.linalg.norm(d, axis=-1, keepdims=True)).reshape(-1, 3)
        return self.radiance_along(np.broadcast_to(cam[:3], d.shape), d).reshape(
            height, width, 3)

    def radiance_along(self, origins, directions):
        """Radiance arriving at ``origins`` (m, 3) from unit ``directions`` (m, 3): that of the
        patch each ray hits first, on the side it hits."""
        corner, e1, e2, n, d1, d2 = self._quads
        t, k, a, b = _first_hit(origins, directions, self._quads)
        out = np.zeros((len(origins), 3))
        hit = k >= 0
        kk = k[hit]
        front = np.einsum("ij,ij->i", n[kk], directions[hit]) < 0.0
        p = self.patches
        ia = np.minimum((a[hit] * p).astype(int), p - 1)
        ib = np.minimum((b[hit] * p).astype(int), p - 1)
        # patches are laid out quad by quad: front side then back side, a-major within a side
        idx = (2 * kk + (~front)) * p * p + ia * p + ib
        out[hit] = self.radiance[idx]
        return out


def solve(scene, patches=4, samples=2, tol=1e-9, max_iterations=10_000):
    """Radiosity solution of ``scene`` (a :class:`~brdf.render.Scene` of quads with Lambertian
    materials, or none, and optional emission; no other lights, no environment).

    Parameters
    ----------
    scene : Scene
    patches : int
        Patches along each edge of each quad. The cost grows as patches^4: the Cornell box
        takes about 12 s at 4 and a minute at 6 on two cores.
    samples : int
        Points along each edge of a patch for the form factor's quadrature and visibility.
    tol : float
        Stop when no radiance changes by more than this in a Jacobi sweep.
    max_iterations : int

    Returns
    -------
    Radiosity

    Notes
    -----
    Points of a patch covered by another quad in its plane facing it (the floor under the
    bottom face of a box standing on it) are left out of the quadrature and of visibility.
    """
    if int(patches) < 1 or int(samples) < 1:
        raise InputError(f"radiosity: patches and samples must be at least 1, got {patches}, "
                         f"{samples}")
    quads, rho, emission = _quads_of(scene)
    mesh = _mesh(quads, rho, emission, int(patches))
    F = _form_factors(mesh, quads, int(samples))
    L, rho_p, le = mesh["le"].copy(), mesh["rho"], mesh["le"]
    for it in range(1, int(max_iterations) + 1):
        new = le + rho_p * (F @ L)
        change = float(np.max(np.abs(new - L)))
        L = new
        if change < tol:
            break
        if not np.isfinite(change):
            break
    if not change < tol:
        # row sums of F above 1 (a patch seeing through to another's surroundings) diverge
        raise InputError(f"radiosity: no convergence in {it} sweeps (last change {change:.3g})")
    return Radiosity(mesh["corner"], mesh["e1"], mesh["e2"], mesh["n"], mesh["quad"],
                     mesh["side"], mesh["area"], L, it, int(patches), quads)


# --- the scene as quads ----------------------------------------------------------------------

def _lambert_albedo(material, k):
    """RGB albedo of a Lambertian material (None: black)."""
    from .scene import Material
    if material is None:
        return np.zeros(3)
    m = material.resolve() if isinstance(material, Material) else Material(material).resolve()
    if getattr(m, "name", None) != "lambert" or len(getattr(m, "lobes", ())) != 1:
        raise InputError(f"radiosity: shape {k}: expected a Lambertian material, got {m}")
    if isinstance(material, Material) and material.textures:
        raise InputError(f"radiosity: shape {k}: textures are not supported")
    values = np.array(list(m.params.values()), float)
    return np.broadcast_to(values, 3).copy()


def _quads_of(scene):
    from .scene import Quad, quad_row, rgb_value
    if scene.lights or scene.environment is not None:
        raise InputError("radiosity: only emissive quads may light the scene (no point, spot, "
                         "directional or environment lights)")
    rows, rho, emission = [], [], []
    for k, s in enumerate(scene.shapes):
        if not isinstance(s, Quad):
            raise InputError(f"radiosity: shape {k}: expected a Quad, got {type(s).__name__}")
        rows.append(quad_row(s, k))
        rho.append(_lambert_albedo(s.material, k))
        le = np.zeros((2, 3))
        if s.emission is not None:
            c = rgb_value(s.emission, f"shape {k} emission")
            sides = {"front": (0,), "back": (1,), "both": (0, 1)}.get(s.sides)
            if sides is None:
                raise InputError(f"shape {k}: sides must be front, back or both, got {s.sides!r}")
            le[list(sides)] = c
        emission.append(le)
    if not rows:
        raise InputError("radiosity: no shapes")
    q = np.array(rows)
    return (q[:, 0], q[:, 1], q[:, 2], q[:, 3], q[:, 4], q[:, 5]), np.array(rho), np.array(emission)


def _mesh(quads, rho, emission, p):
    corner, e1, e2, n = quads[:4]
    nq = len(corner)
    a, b = np.meshgrid(np.arange(p) / p, np.arange(p) / p, indexing="ij")
    a, b = a.ravel(), b.ravel()
    # (quad, side, patch) order; radiance_along relies on it
    c = corner[:, None, None, :] + a[None, None, :, None] * e1[:, None, None, :] \
        + b[None, None, :, None] * e2[:, None, None, :]
    c = np.broadcast_to(c, (nq, 2, p * p, 3))
    side = np.broadcast_to(np.array([1.0, -1.0])[None, :, None], (nq, 2, p * p))
    shape = (nq, 2, p * p)
    return {
        "corner": c.reshape(-1, 3),
        "e1": np.broadcast_to((e1 / p)[:, None, None, :], shape + (3,)).reshape(-1, 3),
        "e2": np.broadcast_to((e2 / p)[:, None, None, :], shape + (3,)).reshape(-1, 3),
        "n": (side[..., None] * n[:, None, None, :]).reshape(-1, 3),
        "quad": np.broadcast_to(np.arange(nq)[:, None, None], shape).reshape(-1),
        "side": side.reshape(-1).astype(int),
        "area": np.broadcast_to((np.linalg.norm(np.cross(e1, e2), axis=1) / p ** 2)[:, None, None],
                                shape).reshape(-1),
        "rho": np.broadcast_to(rho[:, None, None, :], shape + (3,)).reshape(-1, 3),
        "le": np.broadcast_to(emission[:, :, None, :], shape + (3,)).reshape(-1, 3).copy(),
    }


# --- form factors ------------------------------------------------------------------------------

def _points(mesh, s):
    """Centres of an s x s grid of cells over each patch, a hair off its side: (n, s*s, 3)."""
    g = (np.arange(s) + 0.5) / s
    a, b = np.meshgrid(g, g, indexing="ij")
    pts = (mesh["corner"][:, None, :] + a.reshape(1, -1, 1) * mesh["e1"][:, None, :]
           + b.reshape(1, -1, 1) * mesh["e2"][:, None, :])
    scale = 1e-9 * (1.0 + np.max(np.abs(mesh["corner"])))
    return pts + scale * mesh["n"][:, None, :]


def _polygon_form_factor(x, n, poly):
    """Form factor from a differential area at x (normal n) to polygon ``poly`` (..., 4, 3)
    wholly in front of it: (1 / 2 pi) sum_k beta_k n . unit(R_k x R_k+1) (Lambert's contour
    formula, Cohen and Wallace 1993, eq. 4.10)."""
    R = poly - x[..., None, :]
    R = R / np.linalg.norm(R, axis=-1, keepdims=True)
    Rn = np.roll(R, -1, axis=-2)
    cross = np.cross(R, Rn)
    s = np.linalg.norm(cross, axis=-1)
    beta = np.arctan2(s, np.sum(R * Rn, axis=-1))
    term = np.where(s > 0, beta * np.sum(cross * n[..., None, :], axis=-1) / np.where(
        s > 0, s, 1.0), 0.0)
    return np.abs(term.sum(axis=-1)) / (2.0 * math.pi)


def _form_factors(mesh, quads, s, block=48):
    """Dense form-factor matrix F (n, n), row i from patch i (rows in blocks, for numpy)."""
    n_p = len(mesh["area"])
    pts = _points(mesh, s)
    corners = np.stack([mesh["corner"], mesh["corner"] + mesh["e1"],
                        mesh["corner"] + mesh["e1"] + mesh["e2"], mesh["corner"] + mesh["e2"]],
                       axis=1)
    normal = mesh["n"]
    centre = pts.mean(axis=1)
    open_ = ~_buried(pts, mesh, quads)
    F = np.zeros((n_p, n_p))
    for i0 in range(0, n_p, block):
        rows = np.arange(i0, min(n_p, i0 + block))
        # heights of every corner of every patch over the plane of each row's patch
        h = np.einsum("jkc,ic->ijk", corners, normal[rows]) - np.einsum(
            "ic,ic->i", centre[rows], normal[rows])[:, None, None]
        # candidates: some corner in front of i, i's centre in front of j, another quad
        facing = np.einsum("ijc,jc->ij", centre[rows][:, None, :] - mesh["corner"][None],
                           normal) > 0
        pi, pj = np.nonzero(facing & (h.max(axis=2) > 0)
                            & (mesh["quad"][None, :] != mesh["quad"][rows][:, None]))
        if pi.size == 0:
            continue
        hk = h[pi, pj]                                                   # (m, 4)
        x = pts[rows[pi]]                                                # (m, s2, 3)
        ff = _polygon_form_factor(x, np.broadcast_to(normal[rows[pi]][:, None, :], x.shape),
                                  np.broadcast_to(corners[pj][:, None], x.shape[:2] + (4, 3)))
        # patches crossing the plane of i: the contour formula over the part in front of it
        for m in np.flatnonzero(hk.min(axis=1) < -1e-12):
            poly = _clip(corners[pj[m]], hk[m])
            ff[m] = [_polygon_form_factor(xk, normal[rows[pi[m]]], poly) for xk in x[m]]
        # visibility towards the points of j in front of i
        front = (np.einsum("mbc,mc->mb", pts[pj], normal[rows[pi]])
                 > np.einsum("mc,mc->m", centre[rows[pi]], normal[rows[pi]])[:, None])
        vis = _visibility(x, pts[pj], front & open_[pj], quads) * open_[rows[pi]]
        F[rows[pi], pj] = np.mean(ff * vis, axis=1)
    return F


def _buried(pts, mesh, quads):
    """Sample points (n, s2) that lie on another quad facing them, in the same plane (a
    floor under a box's bottom face): they neither see nor are seen."""
    corner, _, _, n, d1, d2 = quads
    flat = pts.reshape(-1, 3)
    own = np.repeat(mesh["quad"], pts.shape[1])
    side_n = np.repeat(mesh["n"], pts.shape[1], axis=0)
    tol = 1e-7 * (1.0 + np.max(np.abs(corner)))
    out = np.zeros(len(flat), bool)
    for k in range(len(corner)):
        rel = flat - corner[k]
        a, b = rel @ d1[k], rel @ d2[k]
        out |= ((np.abs(rel @ n[k]) < tol) & (own != k) & (a > 0) & (a < 1) & (b > 0) & (b < 1)
                & (side_n @ n[k] < -0.999999))
    return out.reshape(pts.shape[:2])


def _clip(poly, h):
    """The part of polygon ``poly`` (k, 3) where the heights ``h`` (k,) are >= 0
    (Sutherland and Hodgman 1974, one plane)."""
    out = []
    for k in range(len(poly)):
        a, b, ha, hb = poly[k], poly[(k + 1) % len(poly)], h[k], h[(k + 1) % len(poly)]
        if ha >= 0:
            out.append(a)
        if (ha >= 0) != (hb >= 0):
            out.append(a + (b - a) * (ha / (ha - hb)))
    return np.array(out)


def _visibility(x, targets, front, quads):
    """Share of the segments from the points x[m, a] to the points targets[m, b] (those with
    ``front[m, b]``) that no quad blocks: (m, a)."""
    m, na, _ = x.shape
    nb = targets.shape[1]
    o = np.broadcast_to(x[:, :, None, :], (m, na, nb, 3)).reshape(-1, 3)
    d = (targets[:, None, :, :] - x[:, :, None, :]).reshape(-1, 3)
    clear = ~_blocked(o, d, quads).reshape(m, na, nb) & front[:, None, :]
    n_front = front.sum(axis=1)[:, None]
    return np.where(n_front > 0, clear.sum(axis=2) / np.maximum(n_front, 1), 1.0)


def _blocked(o, d, quads, eps=1e-6):
    """Whether the segment o + t d, eps < t < 1 - eps, meets any quad."""
    corner, e1, e2, n, d1, d2 = quads
    out = np.zeros(len(o), bool)
    for k in range(len(corner)):
        denom = d @ n[k]
        with np.errstate(divide="ignore", invalid="ignore"):
            t = ((corner[k] - o) @ n[k]) / denom
        ok = (np.abs(denom) > 1e-15) & (t > eps) & (t < 1.0 - eps)
        if not ok.any():
            continue
        rel = o[ok] + t[ok, None] * d[ok] - corner[k]
        a, b = rel @ d1[k], rel @ d2[k]
        hit = (a >= 0) & (a <= 1) & (b >= 0) & (b <= 1)
        idx = np.flatnonzero(ok)
        out[idx[hit]] = True
    return out


def _first_hit(o, d, quads):
    """Nearest quad along each ray o + t d, t > 0: (t, quad or -1, a, b)."""
    corner, e1, e2, n, d1, d2 = quads
    best = np.full(len(o), np.inf)
    k_best = np.full(len(o), -1)
    a_best, b_best = np.zeros(len(o)), np.zeros(len(o))
    for k in range(len(corner)):
        denom = d @ n[k]
        with np.errstate(divide="ignore", invalid="ignore"):
            t = ((corner[k] - o) @ n[k]) / denom
        rel = o + t[:, None] * d - corner[k]
        a, b = rel @ d1[k], rel @ d2[k]
        hit = (np.abs(denom) > 1e-15) & (t > 1e-9) & (t < best) & (a >= 0) & (a <= 1) & \
            (b >= 0) & (b <= 1)
        best[hit], k_best[hit], a_best[hit], b_best[hit] = t[hit], k, a[hit], b[hit]
    return best, k_best, a_best, b_best
