"""Property-based tests of every registered model family (hypothesis).

Parameters are drawn from each family's own declarations (bounds, fit bounds, priors, choices,
nested Fresnel terms, per-channel sizes), so a newly registered family is covered without
touching this file.
"""

import json
import math

import numpy as np
from hypothesis import assume, given, settings
from hypothesis import strategies as st

import brdf
from brdf.models import MODELS, Choice, Nested, Param, Sum
from brdf.errors import ParameterError

#: Shallowest incidence drawn, in degrees from the horizon.
HORIZON_MARGIN_DEG = 0.5


# --- strategies ------------------------------------------------------------------------------

def _range(decl):
    """Interval to draw from: the bounds, with unbounded ends (and the zero end of a log-prior
    parameter) taken from the fit bounds."""
    lo, hi = decl.bounds
    fit_lo, fit_hi = decl.fit_bounds
    lo = lo if math.isfinite(lo) else fit_lo
    hi = hi if math.isfinite(hi) else fit_hi
    if decl.prior == "log" and lo <= 0.0:
        lo = fit_lo
    return lo, hi


def numbers(decl, at_most_one=False):
    """Valid values of a :class:`Param`, log-uniform for log priors.

    ``at_most_one`` caps non-negative per-channel parameters (albedos, ks) at 1, where the
    energy-conserving families promise an albedo of at most 1.
    """
    lo, hi = _range(decl)
    if at_most_one and decl.per_channel and lo >= 0.0:
        hi = min(hi, 1.0)
    if decl.prior == "log":
        return st.floats(math.log(lo), math.log(hi)).map(lambda x: min(max(math.exp(x), lo), hi))
    return st.floats(lo, hi)


@st.composite
def components(draw, cls, nch, at_most_one=False):
    """An instance of ``cls`` (a model family or a Fresnel term) with ``nch`` channels."""
    kwargs = {}
    for decl in cls.PARAMS:
        if isinstance(decl, Param):
            if decl.default is None and not draw(st.booleans()):
                continue  # optional parameters (alpha_y, nv) are left out half the time
            value = numbers(decl, at_most_one)
            if decl.per_channel and nch > 1 and draw(st.booleans()):
                value = st.lists(value, min_size=nch, max_size=nch)
            kwargs[decl.name] = draw(value)
        elif isinstance(decl, Choice):
            kwargs[decl.name] = draw(st.sampled_from(decl.choices))
        elif isinstance(decl, Nested):
            sub = draw(st.sampled_from(decl.registry.classes()))
            kwargs[decl.name] = draw(components(sub, nch))
    try:
        return cls(**kwargs)
    except ParameterError:  # a cross-parameter constraint of the family
        assume(False)


@st.composite
def models(draw, max_lobes=2, at_most_one=False):
    """A registered family with random valid parameters, or a sum of up to ``max_lobes``."""
    nch = draw(st.sampled_from([1, 3]))
    n = draw(st.integers(1, max_lobes))
    lobes = [draw(components(draw(st.sampled_from(MODELS.classes())), nch, at_most_one))
             for _ in range(n)]
    return lobes[0] if n == 1 else Sum(lobes)


@st.composite
def hemisphere(draw):
    """A unit direction on the upper hemisphere (down to HORIZON_MARGIN_DEG above it)."""
    theta = draw(st.floats(0.0, math.radians(90.0 - HORIZON_MARGIN_DEG)))
    phi = draw(st.floats(0.0, 2.0 * math.pi))
    return np.array([math.sin(theta) * math.cos(phi), math.sin(theta) * math.sin(phi),
                     math.cos(theta)])


def pairs(max_size=8):
    """``(wi, wo)`` arrays ``(m, 3)`` of upper-hemisphere directions."""
    return st.lists(st.tuples(hemisphere(), hemisphere()), min_size=1, max_size=max_size).map(
        lambda ps: (np.array([p[0] for p in ps]), np.array([p[1] for p in ps])))


uniforms = st.lists(st.tuples(st.floats(0.0, 1.0, exclude_max=True),
                              st.floats(0.0, 1.0, exclude_max=True)),
                    min_size=1, max_size=16).map(np.array)


# --- properties ------------------------------------------------------------------------------

@settings(max_examples=100)
@given(models(), pairs())
def test_eval_is_finite_and_non_negative(model, directions):
    f = model.eval(*directions)
    assert f.shape == (directions[0].shape[0], model.channels)
    assert np.all(np.isfinite(f)), (str(model), f)
    assert np.all(f >= 0.0), (str(model), f)


@settings(max_examples=100)
@given(models(), pairs())
def test_reciprocity(model, directions):
    assume(model.reciprocal)
    wi, wo = directions
    forward, backward = model.eval(wi, wo), model.eval(wo, wi)
    np.testing.assert_allclose(forward, backward, rtol=1e-7, atol=1e-12 * np.max(forward),
                               err_msg=str(model))


@settings(max_examples=40)
@given(models(max_lobes=1, at_most_one=True), st.lists(hemisphere(), min_size=1, max_size=3))
def test_albedo_at_most_one(model, incident):
    assume(model.energy_conserving)
    albedo, error = model.albedo(np.array(incident), return_error=True)
    assert np.all(albedo <= 1.0 + 1e-3 + error), (str(model), incident, albedo)


@settings(max_examples=40)
@given(models(max_lobes=2), hemisphere())
def test_mirror_images_share_the_albedo(model, wi):
    """Every family declares ``mirror_symmetric``: its albedo is the same at (+-x, +-y, z).
    Integrated one by one, the four images agree within their error estimates (so the
    declaration holds); integrated in one call, they share the first image's integral."""
    assert model.mirror_symmetric, str(model)
    images = wi * np.array([[1.0, 1.0, 1.0], [-1.0, 1.0, 1.0], [1.0, -1.0, 1.0], [-1.0, -1.0, 1.0]])
    first, first_error = model.albedo(images[0], return_error=True)
    for image in images[1:]:
        albedo, error = model.albedo(image, return_error=True)
        assert np.all(np.abs(albedo - first) <= error + first_error + 1e-12), (str(model), wi)
    together, work = model.albedo(images), model._albedo_cubature(images)[2]
    np.testing.assert_array_equal(together, np.broadcast_to(first, together.shape))
    assert np.count_nonzero(work) <= 1 and np.all(work[1:] == 0)


@settings(max_examples=100)
@given(models(), hemisphere(), uniforms)
def test_pdf_and_weight_agree_with_sample(model, wi, u):
    """Samples are valid (pdf > 0), invalid (pdf 0) or delta (pdf inf), never NaN; valid ones
    carry pdf(wi, wo) and the weight f cos / pdf."""
    wo, pdf, weight = model.sample_weighted(wi, u)
    assert not np.any(np.isnan(pdf)) and np.all(pdf >= 0.0), (str(model), pdf)
    valid = np.isfinite(pdf) & (pdf > 0.0)
    assert np.all(np.isfinite(wo[valid])), (str(model), wo)
    assume(valid.any())
    wo, pdf, weight = wo[valid], pdf[valid], weight[valid]
    np.testing.assert_allclose(model.pdf(wi, wo), pdf, rtol=1e-6, err_msg=str(model))
    expected = model.eval(wi, wo) * (wo[:, 2] / pdf)[:, None]
    np.testing.assert_allclose(weight, expected, rtol=1e-6, atol=1e-12, err_msg=str(model))


@settings(max_examples=200)
@given(models(max_lobes=3))
def test_spec_round_trip(model):
    assert brdf.parse(str(model)) == model, str(model)


@settings(max_examples=200)
@given(models(max_lobes=3))
def test_json_round_trip(model):
    assert brdf.from_dict(json.loads(json.dumps(model.to_dict()))) == model, str(model)
