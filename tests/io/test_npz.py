"""Native .npz tables: bit-exact round trips of every kind of table, provenance, and a corpus of
damaged archives."""

import io
import json
import zipfile
from pathlib import Path

import numpy as np
import pytest

import brdf
from brdf.errors import FormatError
from brdf.geometry import directions_from_degrees
from brdf.io import Source, gonio_csv, npz
from brdf.table import AngleTable
from brdf.table import Table

DATA = Path(__file__).resolve().parent.parent / "data"
SAMPLE_ARRAYS = ("wi", "wo", "values", "sigma", "angles")


def exact(a, b):
    """Bit-for-bit equality (NaN payloads and -0.0 included)."""
    a, b = np.asarray(a), np.asarray(b)
    return a.dtype == b.dtype and a.shape == b.shape and a.tobytes() == b.tobytes()


def members(path):
    with np.load(path, allow_pickle=False) as archive:
        return {name: archive[name] for name in archive.files}


def make_table(channels=3, n=50, seed=0, sigma=True, wavelengths=None, **options):
    rng = np.random.default_rng(seed)
    wi = directions_from_degrees(rng.uniform(0, 90, n), rng.uniform(0, 360, n))
    wo = directions_from_degrees(rng.uniform(0, 90, n), rng.uniform(0, 360, n))
    values = rng.standard_normal((n, channels)) * 10.0 ** rng.uniform(-300, 300, (n, channels))
    values[3, 0] = np.nan  # a missing sample
    values[4, -1] = -0.0
    return Table(wi, wo, values, sigma=np.abs(values) * 0.01 if sigma else None,
                 wavelengths=wavelengths, **options)


VARIANTS = {
    "single": dict(channels=1, sigma=False),
    "rgb with sigma": dict(channels=3),
    "spectral": dict(channels=4, wavelengths=[700.0, 400.0, 550.5, 1064.0]),
    "anisotropic with metadata": dict(channels=2, channel_names=("p", "s"), isotropic=False,
                                      metadata={"units": "1/sr", "angles": [1, 2.5],
                                                "note": "line 1\nline 2", "é": None}),
}


@pytest.mark.parametrize("variant", sorted(VARIANTS))
def test_round_trip_is_bit_exact(variant, tmp_path):
    table = make_table(**VARIANTS[variant])
    first = tmp_path / "first.npz"
    npz.write(table, first)
    again = npz.read(first)
    for name in ("wi", "wo", "values", "sigma", "wavelengths"):
        original, read = getattr(table, name), getattr(again, name)
        assert (original is None) == (read is None), name
        if original is not None:
            assert exact(read, original), name
    assert again.channel_names == table.channel_names
    assert again.isotropic == table.isotropic and again.metadata == table.metadata
    assert again.source.format == "npz" and again.source.size == first.stat().st_size
    assert type(again) is Table and again.format == "npz"
    # read -> write -> read: every array of the archive identical; the metadata gains the
    # provenance of the file the samples were read from
    second = tmp_path / "second.npz"
    npz.write(again, second)
    a, b = members(first), members(second)
    assert a.keys() == b.keys()
    assert all(exact(a[k], b[k]) for k in a if k != "metadata")
    assert json.loads(b["metadata"].item()) == {**table.metadata,
                                                "source": again.source.to_dict()}


def test_csv_table_keeps_its_degrees(tmp_path):
    # gonio CSV -> npz -> gonio CSV gives the same file as gonio CSV -> gonio CSV
    original = gonio_csv.read(DATA / "gonio_rgb.csv")
    npz.write(original, tmp_path / "t.npz")
    restored = npz.read(tmp_path / "t.npz")
    assert isinstance(restored, AngleTable) and exact(restored.angles, original.angles)
    assert restored.metadata["source"]["sha256"] == original.source.sha256
    gonio_csv.write(original, tmp_path / "direct.csv")
    gonio_csv.write(restored, tmp_path / "via_npz.csv")
    assert (tmp_path / "via_npz.csv").read_bytes() == (tmp_path / "direct.csv").read_bytes()


def test_provenance_of_the_first_file_is_kept(tmp_path):
    source = Source("/lab/gold.binary", "ab" * 32, "merl", 34992012)
    table = make_table(source=source)
    npz.write(table, tmp_path / "a.npz")
    a = npz.read(tmp_path / "a.npz")
    assert a.metadata["source"] == source.to_dict()
    npz.write(a, tmp_path / "b.npz")  # a's own source is a.npz; the original stays recorded
    assert npz.read(tmp_path / "b.npz").metadata["source"] == source.to_dict()


def test_write_goes_to_exactly_the_path(tmp_path):
    # numpy.savez would append ".npz" to a name without it (the registry's temporary files)
    path = tmp_path / "table.tmp"
    npz.write(make_table(), path)
    assert path.exists() and not (tmp_path / "table.tmp.npz").exists()
    assert npz.sniff(path.read_bytes()[:4096])


def test_registry(tmp_path):
    table = make_table()
    brdf.write(table, tmp_path / "t.npz")
    assert brdf.read(tmp_path / "t.npz").source.format == "npz"
    assert not npz.sniff(b"PK\x03\x04" + bytes(60))
    assert not npz.sniff((DATA / "gonio_rgb.csv").read_bytes())


# -- damaged and foreign archives ------------------------------------------------------------------
def good_members(tmp_path):
    npz.write(make_table(n=6, wavelengths=[400.0, 500.0, 600.0]), tmp_path / "good.npz")
    return members(tmp_path / "good.npz")


def save(tmp_path, arrays):
    path = tmp_path / "bad.npz"
    with open(path, "wb") as f:
        np.savez(f, **arrays)
    return path


def changed(**changes):
    def apply(arrays):
        arrays.update(changes)
        return arrays
    return apply


def removed(*names):
    def apply(arrays):
        for name in names:
            del arrays[name]
        return arrays
    return apply


def nan_direction(arrays):
    arrays["wo"] = arrays["wo"].copy()
    arrays["wo"][2, 1] = np.nan
    return arrays


def scaled(name, factor):
    def apply(arrays):
        arrays[name] = arrays[name] * factor
        return arrays
    return apply


ARCHIVE_CASES = {  # name -> (change to the arrays of a good file, where, text)
    "missing arrays": (removed("wi", "metadata"), "",
                       "missing arrays wi, metadata; a brdf .npz holds format_version, wi"),
    "unknown array": (changed(temperature=np.float64(21.0)), "",
                      "unexpected array temperature"),
    "future version": (changed(format_version=np.int64(2)), "array format_version",
                       "version 2; this reader knows versions 1 to 1"),
    "wi not (N, 3)": (lambda a: changed(wi=a["wi"][:, :2])(a), "array wi",
                      "shape (6, 2); expected (N, 3)"),
    "values rows": (lambda a: changed(values=a["values"][:5])(a), "array values",
                    "shape (5, 3); expected (6, C)"),
    "sigma shape": (lambda a: changed(sigma=a["sigma"][:, :2])(a), "array sigma",
                    "shape (6, 2); expected (6, 3) like values"),
    "channel names": (changed(channel_names=np.array(["a", "b"])), "array channel_names",
                      "shape (2,); expected (3,), one per channel"),
    "integer values": (lambda a: changed(values=np.ones((6, 3), dtype=np.int64))(a),
                       "array values", "dtype int64; expected floating point"),
    "NaN direction": (nan_direction, "array wo", "row 2 = [" ),
    "empty": (lambda a: changed(wi=a["wi"][:0], wo=a["wo"][:0], values=a["values"][:0],
                                sigma=a["sigma"][:0])(a), "array wi", "no samples"),
    "metadata not JSON": (changed(metadata=np.array("{units: 1/sr")), "array metadata",
                          "not JSON"),
    "metadata a list": (changed(metadata=np.array("[1, 2]")), "array metadata",
                        "JSON list; expected a JSON object"),
    "not unit vectors": (scaled("wi", 2.0), "", "wi[0] is not a unit vector"),
    "infinite value": (lambda a: changed(values=np.where(np.arange(3) == 1, np.inf,
                                                         a["values"]))(a), "",
                       "values[0, 1] is infinite"),
    "angles disagree": (changed(angles=np.zeros((6, 4))), "array angles",
                        "row 0 = [0.0, 0.0, 0.0, 0.0] does not describe the directions"),
}


@pytest.mark.parametrize("case", sorted(ARCHIVE_CASES))
def test_damaged_archive(case, tmp_path):
    change, where, text = ARCHIVE_CASES[case]
    path = save(tmp_path, change(good_members(tmp_path)))
    with pytest.raises(FormatError) as info:
        npz.read(path)
    message = str(info.value)
    assert message.startswith(f"{path}:{where}: " if where else f"{path}: "), message
    assert text in message and "\n" not in message, message


def test_pickled_objects_are_refused(tmp_path):
    arrays = good_members(tmp_path)
    arrays["metadata"] = np.array({"units": "1/sr"}, dtype=object)  # unpickling could run code
    path = save(tmp_path, arrays)
    with pytest.raises(FormatError, match=r"bad.npz:array metadata: cannot be read \(Object "
                                          r"arrays cannot be loaded when allow_pickle=False"):
        npz.read(path)


def test_not_a_zip_and_truncated(tmp_path):
    text = tmp_path / "text.npz"
    text.write_text("theta_i,phi_i,theta_o,phi_o,brdf\n")
    with pytest.raises(FormatError, match=r"text.npz:byte 0: not a zip archive"):
        npz.read(text)
    npz.write(make_table(), tmp_path / "whole.npz")
    cut = tmp_path / "cut.npz"
    cut.write_bytes((tmp_path / "whole.npz").read_bytes()[:1000])
    with pytest.raises(FormatError, match=r"cut.npz: truncated or corrupt .npz archive"):
        npz.read(cut)


def test_corrupt_member_is_named(tmp_path):
    npz.write(make_table(), tmp_path / "whole.npz")
    data = bytearray((tmp_path / "whole.npz").read_bytes())
    with zipfile.ZipFile(io.BytesIO(bytes(data))) as z:
        info = z.getinfo("values.npy")
    # flip a byte inside the stored member: its CRC-32 no longer matches
    data[info.header_offset + 200] ^= 0xFF
    (tmp_path / "flip.npz").write_bytes(bytes(data))
    with pytest.raises(FormatError, match=r"flip.npz:array values: cannot be read"):
        npz.read(tmp_path / "flip.npz")


# -- a MERL-size table -----------------------------------------------------------------------------
def test_merl_grid_table_round_trip_is_bit_exact_and_stays_a_grid(tmp_path):
    merl = pytest.importorskip("brdf.io.merl")
    rng = np.random.default_rng(1)
    values = rng.uniform(0.0, 2.0, (merl.SIZE, 3))
    source = Source("/lab/paint.binary", "cd" * 32, "merl", merl.FILE_BYTES)
    table = merl.MerlTable.from_grid_values(values, source=source)
    path = tmp_path / "paint.npz"
    npz.write(table, path)
    again = npz.read(path)
    assert isinstance(again, merl.MerlTable)
    assert again.raw.tobytes() == table.raw.tobytes()
    assert again.metadata["source"] == source.to_dict()
    assert json.loads(members(path)["metadata"].item())["source"]["format"] == "merl"
    merl.write(again, tmp_path / "back.binary")
    merl.write(table, tmp_path / "direct.binary")
    assert (tmp_path / "back.binary").read_bytes() == (tmp_path / "direct.binary").read_bytes()
