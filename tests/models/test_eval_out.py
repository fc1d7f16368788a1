"""``out=`` of Model.eval and Model.pdf on the kernels' path: the same bytes as a new array,
written in place whatever ``out`` held, any leading shape; and every ``out`` the kernels cannot
write into safely refused with one line naming it."""

import numpy as np
import pytest

import brdf
from brdf.errors import InputError
from lobes import upper_directions

SPECS = ["lambert(albedo=[0.5,0.4,0.3]) + ggx(alpha=0.2)",  # the fused Lambertian pass
         "ggx(alpha=0.3, fresnel=schlick(f0=0.04)) + beckmann(alpha=0.5, ks=0.2)",
         "lambert(albedo=0.6)",                                # one channel
         "phong(ks=[0.2,0.3,0.4], n=20) + oren-nayar(albedo=0.5, sigma=0.3)"]


@pytest.mark.parametrize("spec", SPECS)
def test_out_holds_the_same_bytes_as_a_new_array(spec):
    m = brdf.parse(spec)
    rng = np.random.default_rng(7)
    wi = upper_directions(rng, 1000).reshape(10, 100, 3)
    wo = upper_directions(rng, 1000).reshape(10, 100, 3)
    out = np.full((10, 100, m.channels), np.nan)  # nothing it held may leak into the result
    assert m.eval(wi, wo, out=out) is out
    assert np.array_equal(out, m.eval(wi, wo))
    dens = np.full((10, 100), -1.0)
    assert m.pdf(wi, wo, out=dens) is dens
    assert np.array_equal(dens, m.pdf(wi, wo))
    one = np.empty(m.channels)  # a single pair: shape (C,)
    assert np.array_equal(m.eval(wi[0, 0], wo[0, 0], out=one), out[0, 0])
    # a broadcast direction against many
    many = np.empty((100, m.channels))
    assert np.array_equal(m.eval(wi[0, 0], wo[0], out=many), m.eval(wi[0, 0], wo[0]))


def test_a_bad_out_is_refused_naming_it():
    m = brdf.parse(SPECS[0])
    rng = np.random.default_rng(8)
    wi, wo = upper_directions(rng, 6), upper_directions(rng, 6)
    store = np.empty(40)
    cases = [([[0.0] * 3] * 6, r"a float64 numpy array shaped \(6, 3\), got list"),
             (np.empty((6, 2)), r"a float64 array shaped \(6, 3\), got float64 shaped \(6, 2\)"),
             (np.empty((6, 3), np.float32), r"a float64 array shaped \(6, 3\), got float32 shaped \(6, 3\)"),
             (np.empty((3, 6)).T, "a writable C-contiguous"),
             (np.broadcast_to(np.empty(3), (6, 3)), "a writable C-contiguous")]
    for out, message in cases:
        with pytest.raises(InputError, match="^out: expected " + message):
            m.eval(wi, wo, out=out)
    # an out over the inputs would be read while it is written
    inputs = store[:18].reshape(6, 3)
    inputs[:] = wi
    with pytest.raises(InputError, match="^out: shares memory with wi or wo"):
        m.eval(inputs, wo, out=store[9:27].reshape(6, 3))
    with pytest.raises(InputError, match=r"^out: expected a float64 array shaped \(6,\)"):
        m.pdf(wi, wo, out=np.empty((6, 3)))


def test_an_out_is_left_alone_when_a_row_is_refused():
    """A row that is not a unit vector raises naming the row, as without ``out``."""
    m = brdf.parse(SPECS[0])
    wi = np.array([[0.0, 0.0, 1.0], [0.0, 0.0, 2.0]])
    with pytest.raises(InputError, match=r"^wi\[1\] is not a unit vector"):
        m.eval(wi, wi, out=np.empty((2, 3)))
