"""Model.compile's slot map: every numeric parameter of every case maps to exactly the packed
positions its value reaches. The oracle is independent of the layout code: pack the model
again with one parameter entry moved to a distinct value, and diff the two packed arrays."""

import numpy as np
import pytest

import brdf
from brdf.fitting.problem import _numeric, _replace_path
from model_cases import CASES, SUMS

SPECS = [s for specs in CASES.values() for s in specs] + list(SUMS)
#: lobes with a parameter left to fall back on another (alpha_y -> alpha, nv -> nu)
FALLBACKS = ["ggx(alpha=0.3)", "ward(alpha=0.2)", "ashikhmin-shirley(nu=20)"]


def _moved(lobe, path, value, entry, nch):
    """``lobe`` packed for ``nch`` channels with entry ``entry`` of the parameter at ``path``
    set apart from its value (all of it for entry None)."""
    v = np.broadcast_to(np.asarray(value, float), (nch,)).copy() if entry is not None \
        else np.asarray(value, float)
    target = 0.123456789 if np.all(v != 0.123456789) else 0.2345678
    if entry is None:
        v = np.full_like(v, target)
    else:
        v[entry] = target
    return np.asarray(_replace_path(lobe, path, v).pack(nch)), target


@pytest.mark.parametrize("spec", SPECS + FALLBACKS)
@pytest.mark.parametrize("nch", [1, 3])
def test_slots_are_where_the_values_go(spec, nch):
    model = brdf.parse(spec)
    if model.channels not in (1, nch):
        pytest.skip("a 3-channel model packs for 3 channels only")
    compiled = model.compile(nch)
    owned = np.zeros(len(compiled.params), bool)
    for l, lobe in enumerate(model.lobes):
        base = np.asarray(lobe.pack(nch))
        offset = compiled.offsets[l]
        for path, decl, value in _numeric(lobe):
            positions = compiled.slots[l][".".join(path)]
            assert len(positions) == (nch if decl.per_channel else 1), (spec, path)
            for entry, where in enumerate(positions):
                moved, target = _moved(lobe, path, value, entry if decl.per_channel else None,
                                       nch)
                changed = np.flatnonzero(moved != base)
                assert np.array_equal(np.sort(where - offset), changed), (spec, path, entry)
                assert np.all(moved[changed] == target)
                assert not owned[where].any(), (spec, path, "claimed twice")
                owned[where] = True
    # what no numeric parameter owns is a choice, a Fresnel mode or padding: not a number a
    # fit could move
    assert owned.sum() <= len(compiled.params)


def test_a_fallback_parameter_owns_both_blocks():
    compiled = brdf.parse("ggx(alpha=0.3)").compile(1)
    alpha = compiled.slots[0]["alpha"][0]
    assert len(alpha) == 2 and np.all(compiled.params[alpha] == 0.3)
    compiled = brdf.parse("ggx(alpha=0.3, alpha_y=0.1)").compile(1)
    assert len(compiled.slots[0]["alpha"][0]) == 1
    assert compiled.params[compiled.slots[0]["alpha_y"][0]].tolist() == [0.1]


def test_nested_and_global_offsets():
    model = brdf.parse("lambert(albedo=[0.1,0.2,0.3]) + ggx(alpha=0.2, "
                       "fresnel=schlick(f0=[0.9,0.6,0.3]))")
    c = model.compile(3)
    f0 = np.concatenate(c.slots[1]["fresnel.f0"])
    assert c.params[f0].tolist() == [0.9, 0.6, 0.3]
    assert c.params[np.concatenate(c.slots[0]["albedo"])].tolist() == [0.1, 0.2, 0.3]
    assert all(p >= c.offsets[1] for p in f0)
