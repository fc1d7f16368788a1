"""The family table (brdf/models/_kinds.py): every row reaches every dispatcher generated from it
and every consumer of a family (the registry, tests/model_cases.py and the chi-square tests
built on it, the albedo, render materials, export), and the generator refuses a malformed
family with one clear line."""

import importlib
import types

import numpy as np
import pytest

import brdf
from brdf.errors import InputError
from brdf.models import MODELS, _kernels, _kinds
from brdf.render import render, scenes
from model_cases import CASES

ROWS = [pytest.param(row, id=row[0]) for row in _kinds.FAMILIES]


def _class_of(kind):
    owners = [cls for cls in MODELS.classes() if cls.kind == _kinds.CODES[kind]]
    assert len(owners) == 1, f"{kind}: {len(owners)} registered classes have its code"
    return owners[0]


def _directions(n, seed):
    rng = np.random.default_rng(seed)
    v = rng.normal(size=(n, 3))
    v[:, 2] = np.abs(v[:, 2]) + 0.05
    return v / np.linalg.norm(v, axis=1)[:, None]


def test_codes_number_the_rows():
    assert sorted(_kinds.CODES.values()) == list(range(len(_kinds.FAMILIES)))
    for kind, code, _, _ in _kinds.FAMILIES:
        assert getattr(_kinds, kind) == code


def test_every_compiled_class_has_a_row():
    codes = set(_kinds.CODES.values())
    stray = [cls.name for cls in MODELS.classes() if cls.kind >= 0 and cls.kind not in codes]
    assert not stray


@pytest.mark.parametrize("row", ROWS)
def test_row_is_registered_with_cases(row):
    kind, _, module, _ = row
    cls = _class_of(kind)
    assert cls.__module__ == f"brdf.models.{module}"
    assert CASES.get(cls.name), f"{cls.name}: no specs in tests/model_cases.py"
    for spec in CASES[cls.name]:
        assert brdf.parse(spec).kind == cls.kind


@pytest.mark.parametrize("row", ROWS)
def test_row_reaches_every_dispatcher(row):
    """Through the array drivers, each dispatcher's branch of the family: a continuous family
    evaluates, differentiates, samples at its own density and reflects; a delta family has
    eval, grad and pdf 0 (by declaration) and reflects through its sampler."""
    kind, code, _, _ = row
    model = brdf.parse(CASES[_class_of(kind).name][-1])
    kinds, offs, p, nch = model.compile().args
    n = 400
    wi, wo = _directions(n, 1), _directions(n, 2)
    f = np.zeros((n, nch))
    d = np.zeros((p.shape[0], n, nch))
    _kernels.grad_array(kinds, offs, p, nch, wi, wo, f, d)
    pdf = model.pdf(wi, wo)
    u = np.random.default_rng(3).random((n, 2))
    wo_s, pdf_s, weight = model.sample_weighted(wi, u)
    albedo = model.albedo(wi[:8])
    hint = [_kernels.lobe_hint(code, p, nch, *w) for w in wi[:8]]
    assert np.all(np.asarray(hint) > 0.0)
    assert np.all(albedo > 0.0)
    assert np.any(weight > 0.0)
    delta = _kernels.is_delta(code)
    assert delta == model.delta
    assert _kernels.lobe_terms(code) == getattr(
        importlib.import_module(type(model).__module__), "ALBEDO_TERMS", 1)
    if delta:
        assert not f.any() and not d.any() and not pdf.any()
        assert np.all(np.isinf(pdf_s[pdf_s > 0]))
        assert _kernels.delta_reflectance(code, p, nch, 0, wi[0, 2]) > 0.0
    else:
        np.testing.assert_allclose(f, model.eval(wi, wo), rtol=1e-12)  # grad_ vs eval_: ulps
        assert f.any() and d.any() and pdf.any()
        ok = pdf_s > 0
        np.testing.assert_allclose(model.pdf(wi[ok], wo_s[ok]), pdf_s[ok], rtol=1e-9)
        assert _kernels.delta_reflectance(code, p, nch, 0, wi[0, 2]) == 0.0


def test_unknown_kind_falls_through_to_nothing():
    q = np.zeros(4)
    assert _kernels.lobe_pdf(-1, q, 1, 0.0, 0.0, 1.0, 0.0, 0.0, 1.0) == 0.0
    assert _kernels.lobe_sample(-1, q, 1, 0.0, 0.0, 1.0, 0.5, 0.5)[3] == 0.0
    assert _kernels.lobe_hint(-1, q, 1, 0.0, 0.0, 1.0) == 0.0
    assert not _kernels.is_delta(-1)


@pytest.mark.parametrize("row", ROWS)
def test_row_renders_as_a_material(row):
    """A lit sphere of the family's first case: a finite image with light in it."""
    image = render(scenes.lit_sphere(CASES[_class_of(row[0]).name][0]), spp=2, size=(8, 8),
                   seed=1, threads=1, layers=False)
    assert np.all(np.isfinite(image.image)) and image.image.max() > 0.0


@pytest.mark.parametrize("row", ROWS)
@pytest.mark.parametrize("fmt", ["mitsuba", "gltf"])
def test_row_exports_or_says_why_not(row, fmt, tmp_path):
    """Every family exports, exactly or as the closest material, unless it is a delta lobe
    in glTF or too far from anything the format holds (a one-line refusal)."""
    cls = _class_of(row[0])
    spec = CASES[cls.name][0]
    try:
        result = brdf.export(spec, fmt, tmp_path / "out")
    except InputError as e:
        assert ("no reasonable" in str(e) or "delta lobe" in str(e)) and "\n" not in str(e)
    else:
        assert (tmp_path / "out").exists() and (result.exact or result.closest or
                                                result.error > 0.0)


def _fake(**hooks):
    return types.SimpleNamespace(**{name: types.SimpleNamespace(py_func=fn)
                                    for name, fn in hooks.items()})


def test_generator_names_a_missing_hook(monkeypatch):
    monkeypatch.setitem(_kernels._FAMILY_MODULES, "lambert", _fake())
    with pytest.raises(ImportError, match="family LAMBERT: brdf.models.lambert lacks the "
                                          "kernel eval_"):
        _kernels._generate()


def test_generator_refuses_a_delta_lobe_with_a_density(monkeypatch):
    mirror = _kernels._FAMILY_MODULES["mirror"]
    fake = _fake(sample_=mirror.sample_.py_func, hint_=mirror.hint_.py_func,
                 reflectance_=mirror.reflectance_.py_func,
                 pdf_=lambda q, nch, ix, iy, iz, ox, oy, oz: 0.0)
    monkeypatch.setitem(_kernels._FAMILY_MODULES, "mirror", fake)
    with pytest.raises(ImportError, match="family MIRROR: a delta lobe .* remove pdf_"):
        _kernels._generate()


def test_generator_names_an_unknown_hook_argument(monkeypatch):
    lambert = _kernels._FAMILY_MODULES["lambert"]
    hooks = {h: getattr(lambert, h).py_func for h in ("eval_", "grad_", "sample_", "pdf_")}
    hooks["hint_"] = lambda q, nch, ix, iy, iz, colour: 0.0
    monkeypatch.setitem(_kernels._FAMILY_MODULES, "lambert", _fake(**hooks))
    with pytest.raises(ImportError, match="lambert.hint_ takes 'colour'"):
        _kernels._generate()


def test_generated_source_is_the_compiled_one():
    assert _kernels.lobe_eval.py_func.__code__.co_filename == _kernels.__file__
    assert _kernels._generate() == _kernels.DISPATCH_SOURCE
