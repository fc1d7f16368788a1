"""Kernels compiled for a model's own families (brdf.models._kernels.family_kinds): the same
values as the kernels over every family (to rounding), one compile per family set, and the
kernels over every family once brdf.precompile has cached them."""

import contextlib
import os
import subprocess
import sys

import numpy as np
import pytest

import brdf
from brdf.models import _kernels
from brdf.models.base import UNIT_SQ

# a common pair, and a set with a delta lobe, an anisotropic lobe and Beckmann's variant of
# the microfacet module
SPECS = ["lambert(albedo=[0.5,0.4,0.3]) + ggx(alpha=0.2, fresnel=schlick(f0=0.04))",
         "mirror(r=0.2) + ward(alpha=0.2, alpha_y=0.4) + beckmann(alpha=0.3)"]


def _pairs(n=500, seed=0):
    rng = np.random.default_rng(seed)
    v = rng.normal(size=(2, n, 3))
    v[..., 2] = np.abs(v[..., 2]) + 0.02
    v /= np.linalg.norm(v, axis=-1, keepdims=True)
    return np.ascontiguousarray(v[0]), np.ascontiguousarray(v[1])


@pytest.mark.slow
@pytest.mark.parametrize("spec", SPECS)
def test_a_model_s_own_families_give_the_same_bytes_as_every_family(spec):
    c = brdf.parse(spec).compile(3)
    own = _kernels.kinds_of_families(c.kinds)
    assert own.dtype != c.kinds.dtype  # the set of families is in the type
    wi, wo = _pairs()
    u = np.random.default_rng(1).random((len(wi), 2))
    results = []
    for kinds in (np.ascontiguousarray(c.kinds, dtype=np.int64), own):
        f, pdf = np.empty((len(wi), 3)), np.empty(len(wi))
        wo_s, pdf_s, weight = np.empty((len(wi), 3)), np.empty(len(wi)), np.empty((len(wi), 3))
        _kernels.eval_array(kinds, c.offsets, c.params, 3, wi, wo, f, *UNIT_SQ)
        _kernels.pdf_array(kinds, c.offsets, c.params, 3, wi, wo, pdf)
        _kernels.sample_array(kinds, c.offsets, c.params, 3, wi, u, wo_s, pdf_s, weight)
        results.append((f, pdf, wo_s, pdf_s, weight))
    for k, (every, alone) in enumerate(zip(*results)):  # to rounding: kernels compile with
        # fast-math contraction, and LLVM may contract a formula inlined into other code
        # differently. A sampled direction's components (k 2) round at its unit length, so a
        # small one is held to that in absolute terms (AMD znver3: 4.4e-16 off at 0.0596)
        np.testing.assert_allclose(alone, every, rtol=4e-15, atol=4e-15 if k == 2 else 0.0)
    assert np.any(results[0][0] > 0.0) and np.any(results[0][1] > 0.0)


@pytest.mark.slow
def test_a_fit_s_passes_give_the_same_bytes_for_a_model_s_own_families():
    from brdf.fitting.problem import Problem
    table = brdf.measure(SPECS[0], "random:2000", seed=3)
    p = Problem(table, "lambert + ggx(alpha=0.3)")
    X = np.stack([p.x0, p.x0 * 0.9])
    every = p.loss_and_gradient(p.x0), p.channel_losses(X)
    p._family_kinds = _kernels.kinds_of_families(p._kinds)
    alone = p.loss_and_gradient(p.x0), p.channel_losses(X)
    assert alone[0][0] == pytest.approx(every[0][0], rel=1e-14, abs=0.0)
    np.testing.assert_allclose(alone[0][1], every[0][1], rtol=1e-12, atol=0.0)
    np.testing.assert_allclose(alone[1], every[1], rtol=1e-14, atol=0.0)


def test_models_take_the_kernels_over_every_family_once_precompile_cached_them(monkeypatch):
    kinds = np.array([0, 6, 0])
    monkeypatch.setitem(_kernels._EVERY_FAMILY, "cached", False)
    own = _kernels.family_kinds(kinds)
    assert own.dtype.names == ("kind_" + "_".join(map(str, sorted(set(kinds)))),)
    assert np.array_equal(own.view(np.int64), kinds)
    recorded = []
    monkeypatch.setattr(_kernels, "record_every_family", lambda: recorded.append(True))
    with _kernels.every_family():  # as brdf.precompile and brdf.compare compile them
        with _kernels.every_family():
            assert _kernels.family_kinds(kinds).dtype == np.int64
        assert recorded == []
    assert recorded == [True]  # the marker, once the outer context ends
    with _kernels.every_family(record=False):  # work that compiles no model kernels
        assert _kernels.family_kinds(kinds).dtype == np.int64
    assert recorded == [True]
    with _kernels.every_family(record=False):
        with _kernels.every_family():  # an inner context that records still does
            pass
    assert recorded == [True, True]


@pytest.mark.slow
def test_a_first_check_compiles_its_families_and_precompile_records_every_family(tmp_path):
    """On an empty cache: a check compiles, a second loads; brdf.precompile of the tables
    group leaves no marker, of the models group the marker after which a model takes the
    kernels over every family."""
    env = {**os.environ, "NUMBA_CACHE_LOCATOR_CLASSES": "UserProvidedCacheLocator",
           "NUMBA_CACHE_DIR": str(tmp_path / "cache")}
    probe = ("import brdf; from brdf.models import _kernels\n"
             "brdf.check(brdf.parse('lambert(albedo=0.5) + ggx(alpha=0.3)'))\n"
             "print(_kernels.every_family_cached(), "
             "_kernels.family_kinds([0, 6]).dtype.names is None)")

    def run(code):
        done = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True,
                              timeout=900, env=env)
        assert done.returncode == 0, done.stderr
        return done

    cold = run(probe)
    assert cold.stdout.split() == ["False", "False"]
    assert "compiling the model kernels" in cold.stderr
    warm = run(probe)
    assert warm.stdout == cold.stdout and warm.stderr == ""
    marker = _kernels.stamped_marker(_kernels.eval_array, "every-family-kernels")
    # the tables group compiles no model kernels: no marker, models keep their own families'
    run("from brdf.precompile import compile_groups; compile_groups(['tables'])")
    assert not list((tmp_path / "cache").rglob(os.path.basename(marker)))
    run("from brdf.precompile import compile_groups; compile_groups(['models'])")
    assert list((tmp_path / "cache").rglob(os.path.basename(marker)))
    after = run(probe)
    assert after.stdout.split() == ["True", "True"] and after.stderr == ""
    # work over every family (a comparison, the demo) leaves the marker too
    for marker_file in (tmp_path / "cache").rglob(os.path.basename(marker)):
        marker_file.unlink()
    run("import brdf\nfrom brdf.models._kernels import every_family\n"
        "with every_family():\n"
        "    brdf.parse('lambert(albedo=0.5) + ggx(alpha=0.3)').eval([[0, 0, 1]], [[0, 0, 1]])")
    assert list((tmp_path / "cache").rglob(os.path.basename(marker)))


def test_a_comparison_fits_over_every_family(monkeypatch):
    entered = []

    @contextlib.contextmanager
    def every_family():
        entered.append(True)
        yield

    monkeypatch.setattr(_kernels, "every_family", every_family)
    table = brdf.measure(SPECS[0], "random:300", seed=0)
    brdf.compare(table, ["lambert + ggx", "lambert + beckmann"], starts=1)
    assert entered == [True]
