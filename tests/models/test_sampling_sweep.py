"""Every sampler swept over a fine grid of uniform numbers, tails included, at incidences up to
89 degrees and over a range of roughness: each valid sample's pdf is ``pdf(wi, wo)``, its weight
is ``f cos(theta_o) / pdf`` and stays below its family's bound: a band of u where a sampler
goes wrong shows up as one bad sample here, where the chi-square tests see it only as a few
stray samples among 10^6.

The bounds of f cos(theta_o) / pdf for a lobe drawn from its own sampler (in ``_bound``):

- lambert: the albedo (cosine sampling, exact);
- ggx, beckmann: ks F G1(wo) <= ks (visible normals; Heitz 2014, eq. 98);
- modified-phong: ks (n + 2) / (n + 1) cos(theta_o) <= ks (n + 2) / (n + 1);
- phong: 2 pi ks cos(theta_o) / ((n + 1) cos(theta_i)), its 1 / cos(theta_i) unbounded in wi;
- blinn-phong: 8 pi ks N (wi.h) cos(theta_o) / (n + 1) <= 8 pi ks N / (n + 1);
- ward: rho cos^3(theta_h) (wi.h) sqrt(cos_o / cos_i) <= rho / sqrt(cos_i) (original),
  rho cos^3(theta_h) (wi.h) / cos_i <= rho / cos_i (duer), and rho cos_o / (cos_d cos_h) =
  rho (2 - cos_i / (cos_d cos_h)) <= 2 rho (gmd; cos_o = 2 cos_d cos_h - cos_i);
- lafortune with the channels' lobes on one axis: 2 pi |s_c|^n_c cos^(n_c - m) cos_o / (m + 1)
  <= 2 pi max_c |s_c|^n_c / (m + 1), m the smallest exponent (lobes on different axes have
  no bound: their weights are only checked to be finite);
- ashikhmin-shirley, picking the specular term with probability w: F cos_o / max(cos_i, cos_o)
  / w + pi f_d / (1 - w) <= 1 / w + 28/23 max(rd (1 - rs)) / (1 - w);
- a sum picking lobe j with probability p_j: sum_j bound_j / p_j, as f cos / sum_j p_j pdf_j
  <= sum_j f_j cos / (p_j pdf_j).
"""

import math
import time

import numpy as np
import pytest

import brdf
from brdf.models import ashikhmin_shirley, mixed
from chi2 import directions
from model_cases import all_specs

#: Incidences (theta_i deg); the azimuth is 30 deg, off the anisotropic lobes' axes.
THETAS = [0.0, 30.0, 60.0, 80.0, 85.0, 89.0]
PHI_I = 30.0
#: Roughness sweeps on top of tests/model_cases.py, from near-mirror to very rough.
ROUGHNESS = (
    [f"{d}(alpha={a:g})" for d in ("ggx", "beckmann") for a in (0.002, 0.01, 0.05, 0.2, 0.5, 1.0,
                                                                  2.0, 4.0)]
    + [f"beckmann(alpha={a:g}, alpha_y={4 * a:g})" for a in (0.01, 0.2)]
    + [f"ward(rho_s=0.5, alpha={a:g}, variant={v})" for a in (0.005, 0.05, 0.3, 1.0)
       for v in ("original", "duer", "gmd")]
    + [f"{p}(ks=0.5, n={n:g})" for p in ("phong", "modified-phong", "blinn-phong")
       for n in (1.0, 100.0, 1e4, 1e5)]
    + [f"lafortune(cx=-1, cy=-1, cz=1, n={n:g})" for n in (1.0, 100.0, 1e4)]
    + [f"ashikhmin-shirley(rd=0.3, rs=0.2, nu={n:g}, nv={n / 4:g})" for n in (4.0, 400.0, 1e4)]
)
SPECS = [spec for _, spec in all_specs()] + ROUGHNESS
RTOL = 1e-9


def _u_axis():
    """A fine axis of u: the body, and both tails down to 1e-16 from each end."""
    k = np.arange(1, 17)
    body = (np.arange(256) + 0.5) / 256
    ends = np.concatenate([[0.0, 1.0 - 2.0 ** -53], 10.0 ** -k, 1.0 - 10.0 ** -k[:-1],
                           1.0 - np.geomspace(1e-12, 1e-2, 120)])
    return np.unique(np.concatenate([body, ends]))


def _u_grid():
    fine = _u_axis()
    coarse = np.array([0.0, 1e-9, 0.1, 0.3, 0.5, 0.7, 0.9, 1.0 - 1e-9, 1.0 - 2.0 ** -53])
    a, b = np.meshgrid(fine, coarse, indexing="ij")
    u = np.concatenate([np.column_stack([a.ravel(), b.ravel()]),
                        np.column_stack([b.ravel(), a.ravel()])])
    return u[u.max(axis=1) < 1.0]


U = _u_grid()


def _max(v):
    return float(np.max(np.asarray(v, float)))


def _bound(lobe, wi):
    """Upper bound of f cos(theta_o) / pdf of one lobe drawn from its own sampler (see the
    module docstring), or None where the family has none."""
    v, ci = lobe.values, float(wi[2])
    name = lobe.name
    if name == "lambert":
        return _max(v["albedo"])
    if name in ("ggx", "beckmann"):
        return _max(v["ks"])
    if name in ("phong", "modified-phong"):
        n = float(v["n"])
        if name == "phong":
            return 2.0 * math.pi * _max(v["ks"]) / ((n + 1.0) * ci)
        return _max(v["ks"]) * (n + 2.0) / (n + 1.0)
    if name == "oren-nayar":
        # cosine sampling: the weight is albedo (A + B g), and g = max(0, cos dphi) sin(alpha)
        # tan(beta) <= tan(theta_i) for either order of the angles (Oren & Nayar 1994, eq. 30)
        s2 = float(v["sigma"]) ** 2
        a, b = 1.0 - 0.5 * s2 / (s2 + 0.33), 0.45 * s2 / (s2 + 0.09)
        return _max(v["albedo"]) * (a + b * math.sqrt(max(1.0 - ci * ci, 0.0)) / ci)
    if name == "blinn-phong":
        n = float(v["n"])
        if v["normalization"] == "exact":  # Giesen 2009
            norm = (n + 2.0) * (n + 4.0) / (8.0 * math.pi * (2.0 ** (-n / 2.0) + n))
        else:  # Akenine-Moller et al. 2008
            norm = (n + 8.0) / (8.0 * math.pi)
        return 8.0 * math.pi * _max(v["ks"]) * norm / (n + 1.0)
    if name == "ward":
        rho = _max(v["rho_s"])
        return {"original": rho / math.sqrt(ci), "duer": rho / ci, "gmd": 2.0 * rho}[v["variant"]]
    if name == "lafortune":
        c = np.broadcast_arrays(v["cx"], v["cy"], v["cz"], v["n"])
        s = np.stack([np.atleast_1d(c[0]) * wi[0], np.atleast_1d(c[1]) * wi[1],
                      np.atleast_1d(c[2]) * wi[2]], -1)
        norm = np.linalg.norm(s, axis=-1)
        if np.ptp(s / norm[:, None], axis=0).max() > 1e-12:
            return None
        n = np.atleast_1d(c[3])
        return 2.0 * math.pi * float(np.max(norm ** n)) / (float(n.min()) + 1.0)
    if name == "ashikhmin-shirley":
        c = lobe.compile()
        w = ashikhmin_shirley.specular_weight(np.ascontiguousarray(c.params), c.nch, ci)
        rd = np.atleast_1d(v["rd"]) * (1.0 - np.atleast_1d(v["rs"]))
        return (1.0 / w if w > 0.0 else 0.0) + (28.0 / 23.0 * rd.max() / (1.0 - w) if w < 1.0
                                                else 0.0)
    raise AssertionError(f"no weight bound for the family {name}: add it to _bound")


def _mixture_bound(model, wi):
    if len(model.lobes) == 1:
        return _bound(model, wi)
    p = mixed.selection(model, wi[None, :])[:, 0]
    total = 0.0
    for lobe, pj in zip(model.lobes, p):
        if lobe.delta or pj <= 0.0:
            continue
        b = _bound(lobe, wi)
        if b is None:
            return None
        total += b / pj
    return total


def _check(spec):
    """The sweep at every incidence in one batch: the worst relative pdf mismatch (where the
    density is at least 1e-6 of its peak at that incidence), the worst weight over its bound,
    and the number of valid samples."""
    model = brdf.parse(spec)
    n = len(U)
    wis = directions(np.cos(np.radians(THETAS)), np.full(len(THETAS), math.radians(PHI_I)))
    wi = np.repeat(wis, n, axis=0)
    u = np.tile(U, (len(THETAS), 1))
    wo, pdf, weight = model.sample_weighted(wi, u)
    ref = np.zeros_like(pdf)
    valid = (pdf > 0.0) & np.isfinite(pdf)
    ref[valid] = model.pdf(wi[valid], wo[valid])
    f_cos = np.zeros_like(weight)
    f_cos[valid] = model.eval(wi[valid], wo[valid]) * wo[valid, 2:3] / pdf[valid, None]
    worst_mismatch, worst_over = 0.0, 0.0
    for t, theta_i in enumerate(THETAS):
        rows = slice(t * n, (t + 1) * n)
        where = f"{spec} at theta_i {theta_i:g}"
        p, ok = pdf[rows], valid[rows]
        assert not np.any(np.isnan(p)) and np.all(p >= 0.0), where
        assert np.all(weight[rows][p == 0.0] == 0.0), f"{where}: invalid samples carry weight"
        wv, pv, rv, uv = wo[rows][ok], p[ok], ref[rows][ok], U[ok]
        assert np.all(wv[:, 2] > 0.0), f"{where}: valid samples below the horizon"
        np.testing.assert_allclose(np.linalg.norm(wv, axis=1), 1.0, atol=1e-12, err_msg=where)
        # relative, and absolute at the rounding of the peak density: where a cosine power's
        # cos(alpha) is 1e-8, its rounding alone (1e-16 absolute) is 1e-8 of the density
        peak = rv.max(initial=0.0)
        excess = np.abs(pv - rv) / (RTOL * rv + 1e-15 * peak)
        k = int(np.argmax(excess)) if excess.size else 0
        assert not excess.size or excess[k] <= 1.0, (
            f"{where}: sample's pdf {pv[k]:.17g} but pdf(wi, wo) {rv[k]:.17g} at u {uv[k]}")
        body = rv >= 1e-6 * peak
        worst_mismatch = max(worst_mismatch, float(np.max(np.abs(pv - rv)[body] / rv[body],
                                                          initial=0.0)))
        w, fc = weight[rows][ok], f_cos[rows][ok]
        assert np.all(np.isfinite(w)), f"{where}: weights not finite"
        np.testing.assert_allclose(w, fc, rtol=RTOL, atol=1e-12 * fc.max(initial=0.0),
                                   err_msg=where)
        bound = _mixture_bound(model, wis[t])
        if bound is not None and w.size:
            k = np.unravel_index(np.argmax(w), w.shape)[0]
            assert w.max() <= bound * (1.0 + RTOL), (
                f"{where}: weight {w.max():.6g} above the bound {bound:.6g} at u {uv[k]}")
            worst_over = max(worst_over, float(w.max()) / bound)
    return worst_mismatch, worst_over, int(valid.sum())


@pytest.mark.parametrize("spec", SPECS)
def test_sampler_sweep_pdf_and_weight(spec):
    if all(lobe.delta for lobe in brdf.parse(spec).lobes):
        pytest.skip("a delta lobe has no density to compare")
    start = time.perf_counter()
    mismatch, over, count = _check(spec)
    print(f"sweep {spec}: worst pdf mismatch {mismatch:.3g}, worst weight/bound {over:.4f}, "
          f"{count} valid samples, {time.perf_counter() - start:.2f} s")
    assert count > 0


def test_sweep_grid_reaches_both_tails():
    """The grid holds u within 1e-16 of 0 and of 1 (the largest double below 1) in both
    coordinates, and 1 - u from 1e-2 to 1e-9 in geometric steps (the inversion's own sweep in
    test_microfacet.py walks the visible-slope bands at a spacing below their width)."""
    for axis in (0, 1):
        u = U[:, axis]
        assert u.min() == 0.0 and u.max() == 1.0 - 2.0 ** -53
        assert np.any((u > 0.0) & (u <= 1e-16))
        near = np.sort(1.0 - u[(u > 1.0 - 1e-2) & (u < 1.0 - 1e-9)])
        assert np.all(np.diff(np.log(near)) < 0.25)  # geometric steps of under 25 %
