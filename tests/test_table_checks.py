"""brdf.check on measured tables: negative samples counted, reciprocity from measured pairs,
albedo over the interpolant within the measured incidence range."""

import numpy as np
import pytest

import brdf
from brdf.properties import table_reciprocity


def test_clean_table_of_a_physical_model_passes():
    t = brdf.measure("lambert(albedo=0.4) + ggx(ks=0.5, alpha=0.3)", "grid:5,10")
    report = brdf.check(t)
    assert report.passed
    energy = report["energy"]
    model = brdf.parse("lambert(albedo=0.4) + ggx(ks=0.5, alpha=0.3)")
    a = model.albedo(np.array([0.0, 0.0, 1.0]))[0]
    curve = energy.data["curve"]["albedo"][0, 0, 0]
    assert curve == pytest.approx(a, rel=0.01)


def test_negative_samples_are_counted_and_located():
    t = brdf.measure("lambert(albedo=0.05)", "grid:10,30", noise="additive:0.02", seed=2)
    result = brdf.check(t)["non-negativity"]
    negative = int((t.values < 0).sum())
    assert negative > 0 and not result.passed
    assert result.data["negative"] == negative
    assert result.data["fraction"] == pytest.approx(negative / t.values.size)
    k = np.argmin(t.values[:, 0])
    assert result.worst == t.values[k, 0]
    assert result.where["theta_o"] == pytest.approx(t.angles[k, 2])


def test_non_reciprocal_table_fails_and_reciprocal_noise_passes():
    phong = brdf.measure("phong(ks=1, n=8)", "grid:10,30")
    assert not brdf.check(phong)["reciprocity"].passed
    noisy = brdf.measure("lambert(albedo=0.5) + ggx(ks=0.5, alpha=0.3)", "grid:10,30",
                         noise="relative:0.02", seed=4)
    r = table_reciprocity(noisy)
    assert r.passed and r.data["pairs"] > 100
    # two independent 2% errors: the relative difference has median ~ 0.02 * 1.35 / sqrt(2)...
    assert 0.005 < r.data["median"] < 0.05


def test_reciprocity_of_a_table_without_swapped_pairs_is_not_testable():
    from brdf.geometry import directions_from_degrees
    theta_o = np.linspace(0.0, 30.0, 16)
    wi = directions_from_degrees(np.full(16, 60.0), np.zeros(16))
    wo = directions_from_degrees(theta_o, np.full(16, 180.0))
    t = brdf.Table(wi, wo, np.full(16, 0.2))
    r = brdf.check(t)["reciprocity"]
    assert r.passed is None
    assert "not testable" in r.detail
    assert brdf.check(t).passed


def test_energy_violation_of_a_table_is_found():
    t = brdf.measure("blinn-phong(ks=1, n=10, normalization=approx)", "grid:5,5")
    energy = brdf.check(t)["energy"]
    assert not energy.passed and energy.worst > 1.03
    assert energy.where["theta_i"] < 20.0


def test_in_plane_scan_has_no_energy_verdict():
    t = brdf.measure("lambert(albedo=0.5)", "inplane:10")
    report = brdf.check(t)
    assert report["energy"].passed is None
    assert "n/a" in str(report)
    assert report.passed


def test_check_report_of_a_table_converts_to_json():
    import json
    t = brdf.measure("lambert(albedo=0.5)", "grid:15,30")
    data = brdf.check(t).to_dict()
    json.dumps(data, allow_nan=False)
    assert [c["name"] for c in data["checks"]] == ["non-negativity", "reciprocity", "energy"]
