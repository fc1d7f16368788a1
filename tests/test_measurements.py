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


@pytest.mark.parametrize("name", sorted(n for n in listed() if not n.startswith("fits/")))
def test_every_table_reads_and_checks(name):
    table = brdf.read(FOLDER / name)
    assert len(table) > 1000
    report = brdf.check(table, theta_steps=12, anisotropic_steps=(6, 4))
    assert report["non-negativity"].passed is not None


def test_synthetic_tables_regenerate_byte_for_byte(tmp_path):
    spec = importlib.util.spec_from_file_location("make_synthetic",
                                                  FOLDER / "make_synthetic.py")
    make = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(make)
    assert make.main(tmp_path) == 0
    for name in make.TABLES:
        assert (tmp_path / name).read_bytes() == (FOLDER / "synthetic" / name).read_bytes()


def test_synthetic_tables_hold_their_models_within_the_stated_noise():
    for path in sorted((FOLDER / "synthetic").glob("*.csv")):
        table = brdf.read(path)
        model = brdf.parse(table.metadata["model"])
        z = (table.values - model.eval(table.wi, table.wo)) / table.sigma
        assert abs(z.mean()) < 0.1 and 0.9 < z.std() < 1.1, path.name
        assert np.isfinite(z).all()
