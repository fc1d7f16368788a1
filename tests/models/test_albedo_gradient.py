"""Model.albedo_gradient: the albedo's derivatives from the families' analytic gradients,
against central differences of tightly integrated albedos (the energy constraint's Jacobian)."""

import numpy as np
import pytest

import brdf
from brdf.errors import InputError
from brdf.fitting.problem import Problem
from brdf.geometry import directions_from_degrees

WI = directions_from_degrees(np.array([0.0, 30.0, 60.0, 85.0, 89.9]), np.array([0.0, 0.0, 40.0,
                                                                                 0.0, 0.0]))
SPECS = [
    "lambert(albedo=[0.5,0.4,0.3]) + ggx(ks=[0.6,0.5,0.4], alpha=0.2)",
    "lambert(albedo=0.5) + beckmann(ks=0.5, alpha=0.4)",
    "ggx(ks=0.8, alpha=0.3, fresnel=schlick(f0=0.3))",
    "ggx(ks=0.7, alpha=0.15, alpha_y=0.4)",
    "phong(ks=0.5, n=20)",
    "modified-phong(ks=0.5, n=8)",
    "blinn-phong(ks=0.4, n=30)",
    "ward(ks=0.3, alpha=0.2)",
    "lafortune(cx=-1, cy=-1, cz=1, n=12)",
]


def _table(spec):
    channels = brdf.parse(spec).channels
    albedo = "[0.5,0.4,0.3]" if channels == 3 else "0.5"
    return brdf.measure(f"lambert(albedo={albedo})", "random:50", seed=1)


@pytest.mark.parametrize("spec", SPECS)
def test_albedo_jacobian_matches_central_differences(spec):
    problem = Problem(_table(spec), spec)
    x = problem.x0
    a, jac = problem.albedo_jacobian(x, WI)
    assert jac.shape == (len(WI), problem.channels, len(x))
    model_albedo = problem.model(x).albedo(WI)
    np.testing.assert_allclose(a, np.broadcast_to(model_albedo, a.shape), rtol=0, atol=1e-12)
    rows, width = problem.difference_rows(x, 1e-3)
    tight = np.array([np.broadcast_to(problem.model(r).albedo(WI, tol=1e-8, max_panels=8000),
                                      a.shape) for r in rows])
    numeric = problem.difference_jacobian(tight, width)
    scale = max(1.0, np.abs(numeric).max())
    np.testing.assert_allclose(jac, numeric, rtol=0, atol=1e-4 * scale)
    assert np.abs(jac).max() > 0.01  # the parameters do move the albedo


def test_packed_gradient_of_a_scale_parameter_is_the_albedo_per_unit_scale():
    # the albedo is linear in ks: its derivative in ks is the albedo of ks = 1, channel by channel
    model = brdf.parse("ggx(ks=[0.2,0.5,0.8], alpha=0.3)")
    a, dq = model.albedo_gradient(WI)
    unit = brdf.parse("ggx(ks=1, alpha=0.3)").albedo(WI)[:, 0]
    for c in range(3):
        np.testing.assert_allclose(dq[:, c, c], unit, rtol=1e-6)
        np.testing.assert_allclose(a[:, c], model.albedo(WI)[:, c], rtol=0, atol=1e-14)
        for other in set(range(3)) - {c}:
            assert np.all(dq[:, c, other] == 0.0)


@pytest.mark.parametrize("spec", ["mirror(ks=0.5)", "lambert + ashikhmin-shirley"])
def test_delta_and_multi_term_lobes_fall_back_to_differences(spec):
    model = brdf.parse(spec)
    assert not model.albedo_gradient_ready
    with pytest.raises(InputError, match="differentiate its albedo numerically"):
        model.albedo_gradient(WI)
    problem = Problem(_table(spec), spec)
    assert problem.albedo_jacobian(problem.x0, WI) is None


def test_the_albedo_alone_is_compiled_without_its_derivatives():
    # a check needs no derivatives: None (a type of its own) leaves them out of the kernel
    from numba.core import types
    from brdf.models import _kernels
    a = brdf.parse("lambert + ggx(alpha=0.3)").albedo(WI)
    assert a.shape == (len(WI), 1) and np.all(a > 0.0)
    assert any(isinstance(sig[-1], types.NoneType) for sig in _kernels.albedo_array.signatures)
