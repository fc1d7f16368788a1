"""Analytic derivatives of every family's f in its packed parameters (``grad_`` kernels, through
``grad_array``) against central differences of ``eval`` at random valid parameters and random
direction pairs above the horizon."""

import zlib
from types import SimpleNamespace

import numpy as np
import pytest

import brdf
from brdf.fitting.problem import Problem
from brdf.models import _kernels
from lobes import upper_directions
from model_cases import CASES

SPECS = [(family, spec) for family, specs in CASES.items() if family != "mirror"
         for spec in specs]
PAIRS = 400
#: Relative step of the central differences: truncation ~ h^2 and rounding ~ eps / h both stay
#: far below the tolerance.
H = 1e-6
RTOL = 1e-6
ATOL = 1e-8


def continuous_slots(model, nch):
    """Packed positions of the model's numeric parameters (not its choice codes), as the fitter
    finds them: one per channel of each per-channel parameter, each fallback parameter apart."""
    n = 4
    data = SimpleNamespace(wi=np.tile([0.0, 0.0, 1.0], (n, 1)), wo=np.tile([0.0, 0.0, 1.0], (n, 1)),
                           values=np.ones((n, nch)))
    problem = Problem(data, model)
    return sorted({int(s) for p in problem.free for s in np.atleast_1d(p.slots)})


def perturbed(model, rng, nch):
    """The model's packed parameters with each numeric one moved by up to 10 % at random, so that
    derivatives are taken away from round values (and channels differ)."""
    c = model.compile(nch)
    params = c.params.copy()
    for s in continuous_slots(model, nch):
        params[s] *= 1.0 + 0.1 * (2.0 * rng.random() - 1.0)
    return c, params


def eval_packed(c, params, wi, wo):
    out = np.zeros((len(wi), c.nch))
    _kernels.eval_array(c.kinds, c.offsets, params, c.nch, wi, wo, out, 0.0, np.inf)
    return out


@pytest.mark.parametrize("family,spec", SPECS, ids=[s for _, s in SPECS])
def test_analytic_derivatives_match_central_differences(family, spec):
    rng = np.random.default_rng(zlib.crc32(spec.encode()))
    model = brdf.parse(spec)
    nch = 3
    c, params = perturbed(model, rng, nch)
    wi, wo = upper_directions(rng, PAIRS), upper_directions(rng, PAIRS)
    f = np.zeros((PAIRS, nch))
    d = np.zeros((len(params), PAIRS, nch))
    _kernels.grad_array(c.kinds, c.offsets, params, nch, wi, wo, f, d)
    # the same formula: equal to rounding (relative to the largest value: Ward's Gaussian
    # underflows towards 1e-300 far from its lobe, with fewer digits)
    e = eval_packed(c, params, wi, wo)
    assert np.allclose(f, e, rtol=1e-12, atol=1e-14 * np.abs(e).max())
    slots = continuous_slots(model, nch)
    for s in range(len(params)):
        if s not in slots:
            assert not d[s].any(), f"slot {s} is a choice code but has a derivative"
            continue
        h = H * max(1.0, abs(params[s]))
        up, down = params.copy(), params.copy()
        up[s] += h
        down[s] -= h
        ref = (eval_packed(c, up, wi, wo) - eval_packed(c, down, wi, wo)) / (2.0 * h)
        # entry by entry, with an absolute floor for entries far smaller than the largest, and
        # the rounding of the two values of f in the difference (a few ulps of f over 2 h:
        # where f peaks, 89 against a derivative of 1e-3, it alone reaches 1e-8)
        err = np.abs(d[s] - ref)
        rounding = 4.0 * np.finfo(float).eps * np.abs(e) / h
        assert np.all(err <= RTOL * np.abs(ref) + ATOL * np.abs(ref).max() + rounding), (
            s, err.max(), np.abs(ref).max())
