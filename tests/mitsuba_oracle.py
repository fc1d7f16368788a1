"""Mitsuba 3 as an independent oracle: its scalar RGB variant and BSDF evaluation in the local
frame, for the tests that compare our BRDFs with Mitsuba's plugins."""

import numpy as np
import pytest


def load_mitsuba():
    """The ``mitsuba`` module set to ``scalar_rgb`` (no LLVM needed), or skip the test."""
    mi = pytest.importorskip("mitsuba", reason="Mitsuba 3 is the independent oracle")
    mi.set_variant("scalar_rgb")
    return mi


def mitsuba_eval(mi, bsdf, wi, wo):
    """f_r cos(theta_o) from Mitsuba's BSDF.eval in the local frame, (n, 3): Mitsuba's si.wi
    is ``wi`` and the cosine is that of ``wo``, its second argument."""
    ctx = mi.BSDFContext()
    si = mi.SurfaceInteraction3f()
    out = np.empty((len(wi), 3))
    for k in range(len(wi)):
        si.wi = mi.Vector3f(*wi[k])
        v = bsdf.eval(ctx, si, mi.Vector3f(*wo[k]))
        out[k] = [v[0], v[1], v[2]]
    return out
