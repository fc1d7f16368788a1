"""Reading views: responses, images, masks, and the one-line refusals of bad input (library and
``brdf-fit fit-images``, exit status 2)."""

import json

import numpy as np
import pytest
from PIL import Image

import brdf
from brdf.capture import read_photo, read_view, response
from brdf.errors import FormatError, InputError
from brdf.render.image import write_exr
from brdf_cli.main import main


def test_srgb_response_is_the_iec_curve():
    r = response("srgb")
    # IEC 61966-2-1:1999, 4.2: the toe is c / 12.92, mid-grey code 0.5 is 0.2140 linear
    assert r.decode(0.04) == pytest.approx(0.04 / 12.92)
    assert r.decode(0.5) == pytest.approx(0.214041, abs=1e-6)
    assert r.decode(1.0) == pytest.approx(1.0)
    c = np.linspace(0.01, 0.99, 50)
    h = 1e-6
    assert np.allclose(r.slope(c), (r.decode(c + h) - r.decode(c - h)) / (2 * h), rtol=1e-5)


def test_gamma_and_linear_responses():
    assert response("gamma:2.2").decode(0.5) == pytest.approx(0.5 ** 2.2)
    assert response("gamma:2.2").slope(0.5) == pytest.approx(2.2 * 0.5 ** 1.2)
    assert response("linear").decode(0.3) == 0.3
    for bad in ("gamma:0", "gamma:x", "log", 3):
        with pytest.raises(InputError):
            response(bad)


SCENE = {"camera": {"origin": [0, 0, 4], "target": [0, 0, 0], "fov": 30},
         "shapes": [{"type": "sphere", "centre": [0, 0, 0], "radius": 1, "material": "@material"}],
         "lights": [{"type": "point", "position": [2, 2, 3], "intensity": 10}]}


@pytest.fixture
def files(tmp_path):
    scene = tmp_path / "scene.json"
    scene.write_text(json.dumps(SCENE))
    exr = tmp_path / "image.exr"
    write_exr(exr, np.full((12, 16, 3), 0.1))
    return tmp_path, scene, exr


def test_photo_codes_are_decoded_and_saturation_marked(tmp_path):
    codes = np.zeros((4, 5, 3), np.uint8)
    codes[0, 0] = 128
    codes[1, 1] = [255, 10, 10]
    Image.fromarray(codes).save(tmp_path / "p.png")
    p = read_photo(tmp_path / "p.png", "srgb")
    assert p.bits == 8 and p.saturated[1, 1] and not p.saturated[0, 0]
    assert p.linear[0, 0, 0] == pytest.approx(response("srgb").decode(128 / 255))
    assert p.step[0, 0, 0] == pytest.approx(response("srgb").slope(128 / 255) / 255)


def test_exr_alpha_is_the_default_mask(files):
    import OpenEXR
    tmp, scene, _ = files
    rgba = np.full((12, 16, 4), 0.1, np.float32)
    rgba[:, :8, 3] = 0.0
    rgba[:, 8:, 3] = 1.0
    path = tmp / "alpha.exr"
    OpenEXR.File({"compression": OpenEXR.ZIP_COMPRESSION, "type": OpenEXR.scanlineimage},
                 {"RGBA": rgba}).write(str(path))
    v = read_view(scene, path)
    assert v.mask[:, 8:].all() and not v.mask[:, :8].any()


def _one_line(exc, *fragments):
    text = str(exc)
    assert "\n" not in text
    for f in fragments:
        assert f in text, text


def test_grey_image_is_refused_naming_the_file(files):
    tmp, scene, _ = files
    Image.fromarray(np.zeros((12, 16), np.uint8)).save(tmp / "grey.png")
    with pytest.raises(FormatError) as e:
        read_view(scene, tmp / "grey.png", response="srgb")
    _one_line(e.value, "grey.png", "RGB")


def test_scene_without_material_is_refused_naming_the_scene(files):
    tmp, _, exr = files
    doc = json.loads(json.dumps(SCENE))
    doc["materials"] = {"paint": "lambert"}
    doc["shapes"][0]["material"] = "paint"
    (tmp / "known.json").write_text(json.dumps(doc))
    with pytest.raises(FormatError) as e:
        read_view(tmp / "known.json", exr)
    _one_line(e.value, "known.json", "@material")


def test_mask_of_another_size_is_refused_naming_the_mask(files):
    tmp, scene, exr = files
    Image.fromarray(np.full((10, 16), 255, np.uint8)).save(tmp / "mask.png")
    with pytest.raises(FormatError) as e:
        read_view(scene, exr, tmp / "mask.png")
    _one_line(e.value, "mask.png", "16 x 12", "16 x 10")


def test_nan_pixel_is_refused_naming_the_file_and_pixel(files):
    tmp, scene, _ = files
    img = np.full((12, 16, 3), 0.1)
    img[3, 7, 1] = np.nan
    write_exr(tmp / "nan.exr", img)
    with pytest.raises(FormatError) as e:
        read_view(scene, tmp / "nan.exr")
    _one_line(e.value, "nan.exr", "x=7, y=3")


def test_srgb_response_on_an_exr_is_refused(files):
    _, scene, exr = files
    with pytest.raises(InputError) as e:
        read_view(scene, exr, response="srgb")
    _one_line(e.value, "image.exr", "linear")


def test_image_whose_pixels_miss_the_material_is_refused(files):
    tmp, scene, exr = files
    Image.fromarray(np.zeros((12, 16), np.uint8)).save(tmp / "none.png")  # masks every pixel out
    with pytest.raises(InputError) as e:
        brdf.fit_images("lambert", [(scene, exr, tmp / "none.png")], progress=False)
    _one_line(e.value, "image.exr", "@material")


def test_path_mcmc_and_free_scale_without_reference_are_refused(files):
    _, scene, exr = files
    with pytest.raises(InputError, match="tens of thousands of renders"):
        brdf.fit_images("lambert", [(scene, exr)], method="path", mcmc=True)
    for method in ("direct", "path"):
        with pytest.raises(InputError, match="reference"):
            brdf.fit_images("lambert", [(scene, exr)], free_scale=True, method=method,
                            progress=False)


@pytest.mark.parametrize("case", ["grey", "mask", "nan", "scene"])
def test_cli_refuses_bad_views_in_one_line_with_status_2(files, capsys, case):
    tmp, scene, exr = files
    argv = ["fit-images", "lambert", "--view", str(scene), str(exr)]
    if case == "grey":
        Image.fromarray(np.zeros((12, 16), np.uint8)).save(tmp / "grey.png")
        argv[4], name = str(tmp / "grey.png"), "grey.png"
        argv += ["--response", "srgb"]
    elif case == "mask":
        Image.fromarray(np.full((3, 3), 255, np.uint8)).save(tmp / "m.png")
        argv += ["--mask", str(tmp / "m.png")]
        name = "m.png"
    elif case == "nan":
        img = np.full((12, 16, 3), 0.1)
        img[0, 0, 0] = np.nan
        write_exr(tmp / "nan.exr", img)
        argv[4], name = str(tmp / "nan.exr"), "nan.exr"
    else:
        (tmp / "empty.json").write_text(json.dumps({**SCENE, "shapes": [
            {"type": "sphere", "centre": [0, 0, 0], "radius": 1}]}))
        argv[3], name = str(tmp / "empty.json"), "empty.json"
    status = main(argv)
    err = capsys.readouterr().err
    assert status == 2
    lines = err.strip().splitlines()
    assert len(lines) == 1 and lines[0].startswith("brdf-fit: error: ") and name in lines[0], err


def test_16bit_tiff_is_read_at_full_depth_and_16bit_rgb_png_is_refused(tmp_path):
    import tifffile
    codes = np.zeros((3, 4, 3), np.uint16)
    codes[1, 2] = [1000, 30000, 65535]
    tifffile.imwrite(tmp_path / "p.tif", codes, photometric="rgb")
    p = read_photo(tmp_path / "p.tif", "gamma:2.2")
    assert p.bits == 16 and p.saturated[1, 2] and not p.saturated[0, 0]
    assert p.linear[1, 2, 0] == pytest.approx((1000 / 65535) ** 2.2)
    # a 16-bit RGB PNG written by hand (Pillow would read it at 8 bits)
    import struct
    import zlib
    h, w = 2, 3
    rows = b"".join(b"\x00" + np.full((w, 3), 4242, ">u2").tobytes() for _ in range(h))

    def chunk(kind, data):
        return (struct.pack(">I", len(data)) + kind + data
                + struct.pack(">I", zlib.crc32(kind + data) & 0xFFFFFFFF))
    (tmp_path / "p16.png").write_bytes(
        b"\x89PNG\r\n\x1a\n" + chunk(b"IHDR", struct.pack(">IIBBBBB", w, h, 16, 2, 0, 0, 0))
        + chunk(b"IDAT", zlib.compress(rows)) + chunk(b"IEND", b""))
    with pytest.raises(FormatError) as e:
        read_photo(tmp_path / "p16.png", "srgb")
    _one_line(e.value, "p16.png", "TIFF")
