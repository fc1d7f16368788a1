"""Light sources in the renderer (numba kernels): sampling for next-event estimation, and the
radiance and density of emitters that paths hit.

The kernels take the lights as one :data:`Lights` tuple (built by
:meth:`brdf.render.scene.Scene.compile`): ``ltype (nl,)``, ``lf (nl, 16)``, selection
probabilities ``pmf (nl,)``, goniometric tables ``gonio (ng, GONIO_THETA, GONIO_PHI)``, the
environment map ``env (h, w, 3)`` with its pixels' probabilities ``env_pmf (h, w)`` and their
alias table ``env_prob (h w,)``, ``env_alias (h w,)`` (:func:`_alias_pick`), the cosines of its
rows' edges ``env_cos (h + 1,)`` and the cos and sin of its columns' edges
``env_edge (w + 1, 2)`` (:func:`_env_pixel`), and ``env_light``, the index of the environment
(-1: none).

Fields of ``lf`` by type (positions and directions in world space, colours RGB):

- POINT: position 0-2, intensity I 3-5 (W/sr), attenuation a, b, c 6-8;
- SPOT: as POINT, then the axis 9-11, cos(cutoff) 12, falloff exponent 13;
- DIRECTIONAL: direction of travel 0-2, irradiance E 3-5 (W/m^2 normal to the beam);
- AREA: primitive 0, emitting sides 1 (1 front, 2 back, 3 both), area 2, radiance L 3-5;
- GONIO: as POINT, then the axis of theta = 0 9-11, the axis of phi = 0 12-14, table 15;
- ENV: radiance scale 3-5 (times the map, or alone when there is no map), map flag 0, the
  rotation from world to map frame 6-14 (row-major).
"""

import math
from collections import namedtuple

import numpy as np

from .._jit import OPTIMISED, allocating_kernel, inline_kernel, kernel
from ._intersect import SPHERE
from ._materials import wrapped_texels
from .. import sampling

POINT, SPOT, DIRECTIONAL, AREA, GONIO, ENV = 0, 1, 2, 3, 4, 5
FRONT, BACK = 1, 2
#: Resolution of the goniometric tables after resampling (1 degree in theta, 2 in phi).
GONIO_THETA, GONIO_PHI = 181, 181
#: The lights as every kernel takes them (the fields described above).
Lights = namedtuple("Lights", "ltype lf pmf gonio env env_pmf env_prob env_alias env_cos "
                               "env_edge env_light")


@inline_kernel
def attenuation(f, r):
    """1 / (a r^2 + b r + c): the point-light attenuation of classic course notes (OpenGL 1.x
    fixed-function lighting, glLight GL_*_ATTENUATION; a = 1, b = c = 0 is the inverse-square
    law)."""
    return 1.0 / (f[6] * r * r + f[7] * r + f[8])


@inline_kernel
def gonio_intensity(table, f, dx, dy, dz):
    """Scale of the intensity of a goniometric light towards unit direction d: bilinear in its
    (theta, phi) table, theta from the axis f[9:12], phi from f[12:15] about it."""
    ax, ay, az = f[9], f[10], f[11]
    bx, by, bz = f[12], f[13], f[14]
    cx, cy, cz = ay * bz - az * by, az * bx - ax * bz, ax * by - ay * bx
    ct = dx * ax + dy * ay + dz * az
    theta = sampling.arccos(ct)
    phi = sampling.arctan2(dx * cx + dy * cy + dz * cz, dx * bx + dy * by + dz * bz)
    phi = phi + 2.0 * math.pi if phi < 0.0 else phi  # phi % 2 pi without fmod's call
    t = int(f[15])
    x = theta / math.pi * (GONIO_THETA - 1)
    y = phi / (2.0 * math.pi) * (GONIO_PHI - 1)
    i = min(int(x), GONIO_THETA - 2)
    j = min(int(y), GONIO_PHI - 2)
    fx, fy = x - i, y - j
    return ((1.0 - fx) * ((1.0 - fy) * table[t, i, j] + fy * table[t, i, j + 1])
            + fx * ((1.0 - fy) * table[t, i + 1, j] + fy * table[t, i + 1, j + 1]))


# --- environment --------------------------------------------------------------------------------

@inline_kernel
def _env_local(f, dx, dy, dz):
    return (f[6] * dx + f[7] * dy + f[8] * dz,
            f[9] * dx + f[10] * dy + f[11] * dz,
            f[12] * dx + f[13] * dy + f[14] * dz)


@inline_kernel
def _acos(x):
    """arccos x for x in [-1, 1] to 2e-8 (Abramowitz and Stegun 1964, 4.4.46, on |x|, and
    arccos(-x) = pi - arccos x): :func:`_env_pixel` settles its pixel exactly, so it needs no
    more, and :func:`brdf.sampling.arccos` made the environment map's scene 7 % slower."""
    a = min(abs(x), 1.0)
    p = -0.0012624911
    p = p * a + 0.0066700901
    p = p * a - 0.0170881256
    p = p * a + 0.0308918810
    p = p * a - 0.0501743046
    p = p * a + 0.0889789874
    p = p * a - 0.2145988016
    p = p * a + 1.5707963050
    r = math.sqrt(1.0 - a) * p
    return r if x >= 0.0 else math.pi - r


@inline_kernel
def _atan2(y, x):
    """atan2(y, x) in [-pi, pi] to 2e-8: the arctangent of min / max of |x| and |y|
    (Abramowitz and Stegun 1964, 4.4.49, on [0, 1]), then its reflections into the octant (the
    coarse twin of :func:`brdf.sampling.arctan2`, for :func:`_env_pixel`, as :func:`_acos`)."""
    ax, ay = abs(x), abs(y)
    hi = max(ax, ay)
    t = min(ax, ay) / hi if hi > 0.0 else 0.0
    t2 = t * t
    p = 0.0028662257
    p = p * t2 - 0.0161657367
    p = p * t2 + 0.0429096138
    p = p * t2 - 0.0752896400
    p = p * t2 + 0.1065626393
    p = p * t2 - 0.1420889944
    p = p * t2 + 0.1999355085
    p = p * t2 - 0.3333314528
    r = t * (p * t2 + 1.0)
    r = 0.5 * math.pi - r if ay > ax else r
    r = math.pi - r if x < 0.0 else r
    return -r if y < 0.0 else r


@inline_kernel
def _env_pixel(lights, x, y, z):
    """Row and column of the equirectangular map's pixel holding direction (x, y, z) in the
    map's frame, with Mitsuba 3's envmap layout (u = atan2(x, -z) / 2 pi, v = acos(y) / pi,
    row 0 at the top), sin(theta) = sqrt(1 - y^2), and u and v themselves (from the
    polynomials, for :func:`_env_bilinear`).

    The angles come from polynomials (:func:`_acos`, :func:`_atan2`: libm's arctangent,
    arccosine and sine were most of a lookup's time), and the pixel is then settled exactly
    against the tables of its edges: row i holds cos(pi (i + 1) / h) < y <= cos(pi i / h)
    (``env_cos``); column j the azimuths from edge j up to edge j + 1 (``env_edge``: cos and
    sin of 2 pi j / w), the side of an edge that (-z, x) lies on being a cross product's sign."""
    h, w = lights.env.shape[0], lights.env.shape[1]
    ct, edge = lights.env_cos, lights.env_edge
    theta = _acos(y)
    i = min(int(theta * (h / math.pi)), h - 1)
    # the polynomial errs by far less than a row (2e-8 against pi / h): a step to either side
    # at most, taken with selects, not branches (a lane's step is a coin toss)
    i -= (i > 0) & (y > ct[i])
    i += (i < h - 1) & (y <= ct[i + 1])
    phi = _atan2(x, -z)
    j = min(int((phi if phi >= 0.0 else phi + 2.0 * math.pi) * (w / (2.0 * math.pi))), w - 1)
    # cross((cos a, sin a), (-z, x)) = x cos a + z sin a: its sign says which side of edge a
    before = edge[j, 0] * x + edge[j, 1] * z < 0.0
    past = (not before) & (edge[j + 1, 0] * x + edge[j + 1, 1] * z >= 0.0)
    j = (j - 1 if j > 0 else w - 1) if before else ((j + 1 if j < w - 1 else 0) if past else j)
    return (i, j, math.sqrt(max(0.0, (1.0 - y) * (1.0 + y))),
            (phi if phi >= 0.0 else phi + 2.0 * math.pi) / (2.0 * math.pi), theta / math.pi)


@inline_kernel
def _env_bilinear(env, u, v):
    """The map's RGB at (u, v) (u = phi / 2 pi in [0, 1], its columns periodic; v = theta /
    pi), bilinear between pixels as Mitsuba 3's envmap emitter interpolates them
    (src/emitters/envmap.cpp, eval_spectrum): pixel centres at u = (j + 1/2) / w, rows at v =
    i / (h - 1)."""
    h, w = env.shape[0], env.shape[1]
    j0, j1, a = wrapped_texels(u * w - 0.5, w)
    y = min(max(v, 0.0), 1.0) * (h - 1)
    i0 = max(min(int(y), h - 2), 0)
    i1 = min(i0 + 1, h - 1)
    b = y - i0
    c00, c01, c10, c11 = (1.0 - a) * (1.0 - b), a * (1.0 - b), (1.0 - a) * b, a * b
    return (c00 * env[i0, j0, 0] + c01 * env[i0, j1, 0] + c10 * env[i1, j0, 0]
            + c11 * env[i1, j1, 0],
            c00 * env[i0, j0, 1] + c01 * env[i0, j1, 1] + c10 * env[i1, j0, 1]
            + c11 * env[i1, j1, 1],
            c00 * env[i0, j0, 2] + c01 * env[i0, j1, 2] + c10 * env[i1, j0, 2]
            + c11 * env[i1, j1, 2])


@inline_kernel
def env_lookup(lights, e, dx, dy, dz):
    """RGB radiance of environment light e along world direction d (bilinear in the map,
    :func:`_env_bilinear`) and the solid-angle density of :func:`_sample_env` there: uniform
    over the sphere for a constant environment; for a map the probability of the pixel holding
    d (:func:`_env_pixel`) over its solid angle, p(u, v) / (2 pi^2 sin theta) (PBR 3rd ed.
    14.2.4, eq. 14.9's change of variables)."""
    f, env = lights.lf[e], lights.env
    if env_constant(lights, e):
        return f[3], f[4], f[5], 1.0 / (4.0 * math.pi)
    h, w = env.shape[0], env.shape[1]
    x, y, z = _env_local(f, dx, dy, dz)
    i, j, s, u, v = _env_pixel(lights, x, y, z)
    r, g, b = _env_bilinear(env, u, v)
    # a select, not a branch: the caller's loop over the lanes that escaped runs without any
    pdf = lights.env_pmf[i, j] * (h * w) / (2.0 * math.pi * math.pi * s)
    return f[3] * r, f[4] * g, f[5] * b, pdf if s > 0.0 else 0.0


@allocating_kernel
def alias_table(p):
    """Walker's alias table of the discrete distribution ``p`` (n,) (weights >= 0, not all 0),
    built by Vose's method (Walker 1977, "An efficient method for generating discrete random
    variables with general distributions", ACM TOMS 3(3); Vose 1991, "A linear algorithm for
    generating random numbers with a given distribution", IEEE TSE 17(9)): ``(prob, alias)``,
    bin k kept with probability prob[k], else alias[k] (:func:`_alias_pick`)."""
    n = p.shape[0]
    scaled = p * (n / p.sum())
    prob = np.ones(n)
    alias = np.arange(n)
    small, large = np.empty(n, np.int64), np.empty(n, np.int64)
    ns = nl = 0
    for k in range(n):
        ns, nl = _push(k, scaled, small, large, ns, nl)
    while ns > 0 and nl > 0:
        ns -= 1
        nl -= 1
        lo, hi = small[ns], large[nl]
        prob[lo], alias[lo] = scaled[lo], hi
        scaled[hi] = (scaled[hi] + scaled[lo]) - 1.0
        ns, nl = _push(hi, scaled, small, large, ns, nl)
    # what is left on either stack is 1 up to rounding: kept for sure (prob 1, alias itself)
    return prob, alias


@inline_kernel
def _push(k, scaled, small, large, ns, nl):
    """Put bin k on Vose's list of bins below the mean weight or on the list of the others;
    returns the lists' new lengths."""
    if scaled[k] < 1.0:
        small[ns] = k
        return ns + 1, nl
    large[nl] = k
    return ns, nl + 1


@inline_kernel
def _alias_pick(prob, alias, u):
    """Bin drawn from an alias table (:func:`alias_table`) with one uniform number u in [0, 1),
    and what is left of u, rescaled to [0, 1): two independent loads and no search, where
    inverting a CDF was two dependent loads and data-dependent steps (27 of the 45 ns of an
    environment map's sample)."""
    n = prob.shape[0]
    x = u * n
    k = min(int(x), n - 1)
    f = min(x - k, 1.0)
    keep = prob[k]
    own = f < keep
    # selects, not branches: which side of prob[k] u falls on is a coin toss
    rest = f / keep if own else (f - keep) / (1.0 - keep)
    return (k if own else alias[k]), min(rest, _BELOW_ONE)


#: The largest float below 1: a uniform number's rescaled rest stays in [0, 1).
_BELOW_ONE = 1.0 - 2.0 ** -53


@inline_kernel
def env_constant(lights, e):
    """Whether environment light e is constant (no map): :func:`env_lookup` gives the same
    radiance and density in every direction."""
    return lights.lf[e, 0] == 0.0


@inline_kernel
def _sample_constant(f, u1, u2):
    """:func:`_sample_env` of a constant environment (light row ``f``): a direction uniform on
    the sphere."""
    z = 1.0 - 2.0 * u1
    r = math.sqrt(max(0.0, 1.0 - z * z))
    sin_phi, cos_phi = sampling.sincos_turn(u2)
    return r * cos_phi, r * sin_phi, z, f[3], f[4], f[5], 1.0 / (4.0 * math.pi)


@inline_kernel
def _sample_env(lights, e, u1, u2):
    """World direction drawn from environment light e, its radiance and its solid-angle
    density (by :func:`env_lookup`'s formulas: the map bilinear, the density the drawn
    pixel's, piecewise constant). The pixel comes from the alias table of the pixels'
    probabilities with u1, the point within it from the rest of u1 (in theta) and u2 (in
    phi)."""
    f, env = lights.lf[e], lights.env
    if env_constant(lights, e):
        return _sample_constant(f, u1, u2)
    h, w = env.shape[0], env.shape[1]
    k, fu = _alias_pick(lights.env_prob, lights.env_alias, u1)
    # row and column of pixel k (row-major) without an integer division: k + 1/2 is never
    # within rounding of a multiple of w
    i = int((k + 0.5) * (1.0 / w))
    j = k - i * w
    fv = u2
    # theta = pi (i + fu) / h and phi = 2 pi (j + fv) / w, in turns
    sin_t, cos_t = sampling.sincos_turn(0.5 * (i + fu) / h)
    sin_p, cos_p = sampling.sincos_turn((j + fv) / w)
    # inverse of _env_pixel: x = sin(theta) sin(phi), y = cos(theta), z = -sin(theta) cos(phi)
    x, y, z = sin_t * sin_p, cos_t, -sin_t * cos_p
    # the frame is a rotation: world = frame^T local
    dx = f[6] * x + f[9] * y + f[12] * z
    dy = f[7] * x + f[10] * y + f[13] * z
    dz = f[8] * x + f[11] * y + f[14] * z
    # radiance and density as env_lookup has them, from (i, j), (u, v) and sin theta as
    # drawn: finding the pixel again from d cost an arctangent and an arccosine a sample
    if sin_t <= 0.0:
        return dx, dy, dz, 0.0, 0.0, 0.0, 0.0
    r, g, b = _env_bilinear(env, (j + fv) / w, (i + fu) / h)
    return (dx, dy, dz, f[3] * r, f[4] * g, f[5] * b,
            lights.env_pmf[i, j] * (h * w) / (2.0 * math.pi * math.pi * sin_t))


@inline_kernel
def env_samples(lights, e, u, m, s):
    """:func:`sample_light` of environment light e for m paths at once: the uniform pairs in
    ``u[0, :m, 0:2]`` (the first rescaled by :func:`pick_light`), each sample's direction,
    radiance and solid-angle density into ``s[0, :m, 0:7]`` (both work space on the caller's
    stack). The draw depends on the numbers alone, not on the vertex, so a caller draws a
    block of them in one loop without calls or stores to its own arrays, which LLVM may run
    in SIMD lanes, where one at a time in the vertex loop its chain of dependent loads and
    polynomials waited lane after lane. A constant environment's draws have a loop of their
    own, without the map's branch."""
    if env_constant(lights, e):
        f = lights.lf[e]
        for k in range(m):
            (s[0, k, 0], s[0, k, 1], s[0, k, 2], s[0, k, 3], s[0, k, 4], s[0, k, 5],
             s[0, k, 6]) = _sample_constant(f, u[0, k, 0], u[0, k, 1])
        return
    for k in range(m):
        s[0, k, 0], s[0, k, 1], s[0, k, 2], s[0, k, 3], s[0, k, 4], s[0, k, 5], s[0, k, 6] = (
            _sample_env(lights, e, u[0, k, 0], u[0, k, 1]))


# --- area lights ------------------------------------------------------------------------------

@inline_kernel
def emits_towards(f, nx, ny, nz, dx, dy, dz):
    """Whether an area light with outward (geometric) normal n emits along direction d (of any
    length: only its sign against n counts)."""
    c = nx * dx + ny * dy + nz * dz
    sides = int(f[1])
    return (c > 0.0 and (sides & FRONT) != 0) or (c < 0.0 and (sides & BACK) != 0)


@inline_kernel
def area_pdf(geo, f, px, py, pz, vx, vy, vz, dist, nx, ny, nz):
    """Solid-angle density, seen from p, with which :func:`_sample_area` draws the point
    p + v on the light (|v| = dist, outward normal n)."""
    i, prim = int(f[0]), geo.prim
    if prim[i, 0] == SPHERE:
        s = geo.sph[prim[i, 1]]
        cx, cy, cz, r = s[0] - px, s[1] - py, s[2] - pz, s[3]
        dc2 = cx * cx + cy * cy + cz * cz
        if dc2 > r * r * (1.0 + 1e-9):
            # uniform over the cone of the sphere's silhouette (PBR 4th ed. 6.2.4)
            cos_max = math.sqrt(max(0.0, 1.0 - r * r / dc2))
            return 1.0 / (2.0 * math.pi * (1.0 - cos_max))
    # uniform by area: dA = r^2 / cos d(omega), with cos = |n . v| / r: the unnormalised v
    # spares next-event estimation a division on its longest chain of waits (perf)
    nv = abs(nx * vx + ny * vy + nz * vz)
    if nv <= 0.0:
        return 0.0
    return dist * dist * dist / (f[2] * nv)


@inline_kernel
def _sample_area(geo, f, px, py, pz, u1, u2):
    """A point on area light f seen from p: ``(qx, qy, qz, nx, ny, nz)``."""
    i = int(f[0])
    j = geo.prim[i, 1]
    if geo.prim[i, 0] == SPHERE:
        s = geo.sph[j]
        cx, cy, cz, r = s[0], s[1], s[2], s[3]
        wx, wy, wz = cx - px, cy - py, cz - pz
        dc2 = wx * wx + wy * wy + wz * wz
        if dc2 > r * r * (1.0 + 1e-9):
            # a direction in the silhouette cone, then the nearer point of the sphere along it
            dc = math.sqrt(dc2)
            cos_max = math.sqrt(max(0.0, 1.0 - r * r / dc2))
            ct = 1.0 - u1 * (1.0 - cos_max)
            st = math.sqrt(max(0.0, 1.0 - ct * ct))
            sin_phi, cos_phi = sampling.sincos_turn(u2)
            dx, dy, dz = sampling.from_axis_frame(st * cos_phi, st * sin_phi, ct,
                                                  wx / dc, wy / dc, wz / dc)
            b = dx * wx + dy * wy + dz * wz
            t = b - math.sqrt(max(0.0, b * b - dc2 + r * r))
            qx, qy, qz = px + t * dx, py + t * dy, pz + t * dz
        else:
            z = 1.0 - 2.0 * u1
            rr = math.sqrt(max(0.0, 1.0 - z * z))
            sin_phi, cos_phi = sampling.sincos_turn(u2)
            qx, qy, qz = cx + r * rr * cos_phi, cy + r * rr * sin_phi, cz + r * z
        return qx, qy, qz, (qx - cx) / r, (qy - cy) / r, (qz - cz) / r
    g = geo.quad[j]
    return (g[0, 0] + u1 * g[1, 0] + u2 * g[2, 0], g[0, 1] + u1 * g[1, 1] + u2 * g[2, 1],
            g[0, 2] + u1 * g[1, 2] + u2 * g[2, 2], g[3, 0], g[3, 1], g[3, 2])


# --- next-event estimation ----------------------------------------------------------------------

@inline_kernel
def pick_light(pmf, u):
    """A light index drawn with probabilities ``pmf``, and ``u`` rescaled within its share."""
    acc = 0.0
    n = pmf.shape[0]
    for l in range(n):
        if u < acc + pmf[l] or l == n - 1:
            return l, rescaled_pick(u, acc, pmf[l])
        acc += pmf[l]
    return n - 1, u


@inline_kernel
def rescaled_pick(u, acc, p):
    """``u`` rescaled within the share [acc, acc + p) of the light it picked, kept in [0, 1)."""
    return min(max((u - acc) / p, 0.0), 0.9999999999999999)


@kernel(linked=OPTIMISED)
def _cos_power(c, n):
    """c^n for a spotlight's falloff: by squaring where n is a whole number up to 64 (c^2 is
    c * c, to the bit), else libm's pow, which costs 13 ns a call."""
    if not (n <= 64.0 and n == math.floor(n)):
        return c ** n
    k = int(n)
    r = 1.0
    while k > 0:
        if k & 1:
            r *= c
        c *= c
        k >>= 1
    return r


@inline_kernel
def sample_light(lights, geo, l, px, py, pz, u1, u2, li):
    """Incident light at p from light l: returns ``(vx, vy, vz, inv, dist, pdf)`` with v
    pointing towards the light and ``v * inv`` the unit direction d (directional and
    environment light give a unit v and inv 1), dist the shadow-ray length (inf for
    directional and environment light) and pdf its solid-angle density (inf for delta lights,
    0 for none), and writes the incident radiance (or, for delta lights, irradiance normal to
    d) into li[:3]. A caller tests which side of a surface the light lies on from v, without
    waiting for the division that makes it a unit vector (perf: the longest wait of
    next-event estimation)."""
    t = lights.ltype[l]
    f = lights.lf[l]
    if t == POINT or t == SPOT or t == GONIO:
        vx, vy, vz = f[0] - px, f[1] - py, f[2] - pz
        r = math.sqrt(vx * vx + vy * vy + vz * vz)
        inv = 1.0 / r
        dx, dy, dz = vx * inv, vy * inv, vz * inv
        s = attenuation(f, r)  # E = I cos / (a r^2 + b r + c); the cosine is the receiver's
        if t == SPOT:
            ca = -(dx * f[9] + dy * f[10] + dz * f[11])
            # the spotlight of classic course notes: I cos^n(angle to the axis) inside the cone
            s = s * _cos_power(ca, f[13]) if ca >= f[12] else 0.0
        elif t == GONIO:
            s *= gonio_intensity(lights.gonio, f, -dx, -dy, -dz)
        for c in range(3):
            li[c] = f[3 + c] * s
        return vx, vy, vz, inv, r, math.inf
    if t == DIRECTIONAL:
        for c in range(3):
            li[c] = f[3 + c]
        return -f[0], -f[1], -f[2], 1.0, math.inf, math.inf
    if t == AREA:
        qx, qy, qz, nx, ny, nz = _sample_area(geo, f, px, py, pz, u1, u2)
        vx, vy, vz = qx - px, qy - py, qz - pz
        r2 = vx * vx + vy * vy + vz * vz
        if r2 <= 0.0:
            return 0.0, 0.0, 1.0, 1.0, 0.0, 0.0
        r = math.sqrt(r2)
        # facing and density from v itself, so that they need not wait for the division
        if not emits_towards(f, nx, ny, nz, -vx, -vy, -vz):
            return vx, vy, vz, 1.0 / r, r, 0.0
        for c in range(3):
            li[c] = f[3 + c]
        return vx, vy, vz, 1.0 / r, r, area_pdf(geo, f, px, py, pz, vx, vy, vz, r, nx, ny, nz)
    dx, dy, dz, li[0], li[1], li[2], pdf = _sample_env(lights, l, u1, u2)
    return dx, dy, dz, 1.0, math.inf, pdf
