"""The bundled data in measurements/: every file reads, the published checksums hold, the
synthetic tables regenerate byte for byte and carry the model that made them."""

import hashlib
import importlib.util
from pathlib import Path

import numpy as np
import pytest

import brdf

FOLDER = Path(__file__).resolve().parents[1] / "measurements"


def listed():
    lines = (FOLDER / "SHA256SUMS.txt").read_text().splitlines()
    return dict(reversed(line.split(None, 1)) for line in lines if line)


def test_checksums_and_size():
    sums = listed()
    files = sorted(str(p.relative_to(FOLDER)) for p in FOLDER.rglob("*")
                   if p.is_file() and p.suffix in (".bsdf", ".csv"))
    assert sorted(sums) == files
    for name, digest in sums.items():
        assert hashlib.sha256((FOLDER / name).read_bytes()).hexdigest() == digest, name
    total = sum(p.stat().st_size for p in FOLDER.rglob("*") if p.is_file())
    assert total < 10 * 2**20


#: The verdicts (non-negativity, reciprocity, energy) each bundled table must get; None is
#: "not testable". Two RGL paints hold negative values (2.6 % and 4.8 % of them, down to
#: -0.44 1/sr: RGB from spectra) and swapped pairs 20 % apart at the 95th percentile; a
#: random scan has no swapped pairs and an in-plane scan no albedo.
VERDICTS = {
    "rgl/cc_ibiza_sunset_rgb.bsdf": (False, False, True),
    "rgl/colodur_napoli_4f_rgb.bsdf": (True, True, True),
    "rgl/paper_white_rgb.bsdf": (True, True, True),
    "rgl/vch_golden_yellow_rgb.bsdf": (False, False, True),
    "synthetic/brushed_metal_random.csv": (True, None, True),
    "synthetic/matte_paint_inplane.csv": (True, True, None),
    "synthetic/plastic_grid.csv": (True, True, True),
}
#: Known wrong verdicts. The brushed metal's model (GGX, ks 0.95, alpha 0.1 x 0.35) has albedo
#: at most 0.85, but the table's 9,000 random samples interpolate its sharp lobe so coarsely that
#: the integral reaches 2.06 at 85.5 degrees (and is 20 % high at 30): the energy check should
#: call that not testable rather than fail it.
WRONG = {("synthetic/brushed_metal_random.csv", "energy")}


def test_every_bundled_table_has_a_verdict():
    assert sorted(VERDICTS) == sorted(n for n in listed() if not n.startswith("fits/"))


@pytest.mark.parametrize("name, check", [
    pytest.param(name, check, marks=[pytest.mark.xfail(strict=True, reason="see WRONG")]
                 if (name, check) in WRONG else [])
    for name in sorted(VERDICTS) for check in ("non-negativity", "reciprocity", "energy")])
def test_every_table_reads_and_gets_its_verdict(name, check, checked):
    table, report = checked(name)
    assert len(table) > 1000
    expected = VERDICTS[name][("non-negativity", "reciprocity", "energy").index(check)]
    assert report[check].passed is expected, report[check].detail


@pytest.fixture(scope="module")
def checked():
    cache = {}

    def get(name):
        if name not in cache:
            table = brdf.read(FOLDER / name)
            cache[name] = table, brdf.check(table, theta_steps=12, anisotropic_steps=(6, 4))
        return cache[name]
    return get


def _make_synthetic():
    spec = importlib.util.spec_from_file_location("make_synthetic",
                                                  FOLDER / "make_synthetic.py")
    make = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(make)
    return make


def test_synthetic_tables_regenerate(tmp_path):
    """The same seed gives the same bytes in one run; against the checked-in files the header
    holds exactly, the angles to 1e-14 and the values to 1e-12. The last bits are not the
    files': numpy's SIMD arccos and arctan2 round the random geometry's angles differently on
    another processor (CI's differed from ours by 1 ulp in 4 % of them), and a formula
    rewritten in an equivalent order, or a kernel compiled on another machine, may round the
    model's value differently. The noise draws themselves are fixed by the seed."""
    make = _make_synthetic()
    (tmp_path / "a").mkdir(), (tmp_path / "b").mkdir()
    assert make.main(tmp_path / "a") == 0 and make.main(tmp_path / "b") == 0
    for name in make.TABLES:
        again = (tmp_path / "a" / name).read_text()
        assert again == (tmp_path / "b" / name).read_text(), name
        mine, theirs = (_split(text) for text in (again, (FOLDER / "synthetic" / name).read_text()))
        assert mine[0] == theirs[0] and mine[1].shape == theirs[1].shape, name
        np.testing.assert_allclose(mine[1][:, :4], theirs[1][:, :4], rtol=1e-14, atol=1e-12)
        np.testing.assert_allclose(mine[1][:, 4:], theirs[1][:, 4:], rtol=1e-12, atol=0)


def _split(text):
    """Comment and header lines, and the numbers of a gonio CSV."""
    lines = text.splitlines()
    head = [line for line in lines if line.startswith("#") or line[:1].isalpha()]
    rows = [line.split(",") for line in lines if line and line not in head]
    return head, np.array(rows, dtype=float)


def test_synthetic_tables_hold_their_models_within_the_stated_noise():
    for path in sorted((FOLDER / "synthetic").glob("*.csv")):
        table = brdf.read(path)
        model = brdf.parse(table.metadata["model"])
        z = (table.values - model.eval(table.wi, table.wo)) / table.sigma
        assert abs(z.mean()) < 0.1 and 0.9 < z.std() < 1.1, path.name
        assert np.isfinite(z).all()
