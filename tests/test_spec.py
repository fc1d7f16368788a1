"""The spec language: round trips, positional arguments, aliases, nesting, channels, errors."""

import json
import re

import numpy as np
import pytest

import brdf
from brdf.errors import ParameterError, SpecError
from brdf.models import GGX, Lambert, Schlick, Sum
from model_cases import all_specs

SPECS = [spec for _, spec in all_specs()]


def _column(exc_info):
    match = re.search(r"column (\d+)", str(exc_info.value))
    assert match, f"no column in {exc_info.value}"
    return int(match.group(1))


@pytest.mark.parametrize("spec", SPECS)
def test_str_parses_back_to_an_equal_model(spec):
    model = brdf.parse(spec)
    text = str(model)
    assert brdf.parse(text) == model
    assert str(brdf.parse(text)) == text  # printing is a fixed point


@pytest.mark.parametrize("spec", SPECS)
def test_json_round_trip(spec):
    model = brdf.parse(spec)
    text = json.dumps(model.to_dict())
    assert brdf.from_json(text) == model
    assert brdf.from_dict(json.loads(text)) == model


def test_round_trip_keeps_every_digit():
    model = brdf.parse("ggx(alpha=0.1234567890123456, ks=[0.1,0.2,0.30000000000000004])")
    again = brdf.parse(str(model))
    assert float(again["alpha"]) == 0.1234567890123456
    assert again["ks"][2] == 0.30000000000000004


def test_parse_returns_models_unchanged():
    model = brdf.parse("lambert")
    assert brdf.parse(model) is model


def test_defaults_and_spacing():
    assert brdf.parse("lambert") == brdf.parse(" lambert ( ) ") == Lambert(albedo=0.5)
    assert brdf.parse("ggx") == GGX()


def test_positional_arguments_follow_declaration_order():
    assert brdf.parse("ggx(0.5, 0.2)") == GGX(ks=0.5, alpha=0.2)
    assert brdf.parse("lambert(0.3)") == Lambert(albedo=0.3)
    assert brdf.parse("ggx(0.5, alpha=0.2)") == GGX(ks=0.5, alpha=0.2)


def test_parameter_aliases():
    assert brdf.parse("ggx(alpha_x=0.2, alpha_y=0.4)") == brdf.parse("ggx(alpha=0.2, alpha_y=0.4)")
    assert brdf.parse("lambert(rho=0.3)") == brdf.parse("lambert(albedo=0.3)")
    assert str(brdf.parse("lambert(rho=0.3)")) == "lambert(albedo=0.3)"  # printed canonically


def test_model_aliases():
    assert brdf.parse("diffuse(0.3)") == Lambert(albedo=0.3)
    assert brdf.parse("trowbridge-reitz(alpha=0.3)") == GGX(alpha=0.3)


def test_nested_fresnel():
    model = brdf.parse("ggx(alpha=0.2, fresnel=schlick(f0=0.04))")
    assert model["fresnel"] == Schlick(f0=0.04)
    assert brdf.parse("ggx(fresnel=schlick(0.04))") == brdf.parse("ggx(fresnel=schlick(f0=0.04))")
    assert brdf.parse("ggx(fresnel=none)") == brdf.parse("ggx")
    assert brdf.parse("ggx(fresnel=schlick)")["fresnel"] == Schlick()
    conductor = brdf.parse("ggx(fresnel=conductor(eta=[0.2,0.9,1.1], k=[3.9,2.4,2.2]))")
    assert conductor.channels == 3
    assert conductor.params["ggx.fresnel.k[2]"] == 2.2


def test_per_channel_lists():
    model = brdf.parse("lambert(albedo=[0.5,0.4,0.3]) + ggx(alpha=0.2)")
    assert isinstance(model, Sum) and model.channels == 3
    assert model.eval(np.array([0, 0, 1.0]), np.array([0, 0, 1.0])).shape == (3,)
    assert model.params["lambert.albedo[1]"] == 0.4
    assert brdf.parse("lambert(albedo=[0.5])") == brdf.parse("lambert(albedo=0.5)")


def test_sums_of_one_and_many_channels():
    many = "[" + ",".join(["0.5"] * 31) + "]"
    assert brdf.parse(f"lambert(albedo={many}) + ggx(alpha=0.2)").channels == 31
    with pytest.raises(ParameterError, match=r"channels \(3, 31\)"):
        brdf.parse(f"lambert(albedo=[0.5,0.4,0.3]) + ggx(ks={many})")
    with pytest.raises(ParameterError, match=r"channels \(2, 3\)"):
        brdf.parse("ggx(ks=[0.1,0.2,0.3], fresnel=schlick(f0=[0.1,0.2]))")


# --- errors ----------------------------------------------------------------------------------

def test_unknown_model_lists_the_valid_ones():
    with pytest.raises(SpecError, match="unknown model 'lamburt'") as exc:
        brdf.parse("lambert + lamburt(albedo=0.5)")
    assert _column(exc) == 11
    for name in brdf.models.MODELS.names():
        assert name in str(exc.value)


def test_unknown_parameter_lists_the_models_parameters():
    with pytest.raises(SpecError, match="unknown parameter 'alpah'") as exc:
        brdf.parse("lambert + ggx(alpah=0.2)")
    assert _column(exc) == 15  # the misspelt parameter itself
    assert "ks, alpha, alpha_y, masking, fresnel" in str(exc.value)


@pytest.mark.parametrize("spec, bounds", [("lambert(albedo=1.5)", "[0, 1]"),
                                          ("lambert(albedo=[0.5,-0.1,0.2])", "[0, 1]"),
                                          ("ggx(alpha=5)", "[0.0001, 4]")])
def test_out_of_bounds_says_the_bounds(spec, bounds):
    with pytest.raises(ParameterError) as exc:
        brdf.parse(spec)
    assert bounds in str(exc.value) and _column(exc) == 1


@pytest.mark.parametrize("value", ["nan", "inf", "-inf", "[0.1,nan,0.2]"])
def test_non_finite_values_are_rejected(value):
    with pytest.raises(ParameterError, match="finite") as exc:
        brdf.parse(f"lambert(albedo={value})")
    assert _column(exc) == 1


def test_nested_error_points_at_the_nested_term():
    with pytest.raises(ParameterError, match=r"f0=2 is outside its bounds \[0, 1\]") as exc:
        brdf.parse("ggx(fresnel=schlick(f0=2))")
    assert str(exc.value).count("column") == 1 and _column(exc) == 13


@pytest.mark.parametrize("spec, column", [
    ("ggx(alpha=0.2", 14),          # missing ')'
    ("ggx(alpha=)", 11),            # missing value
    ("lambert +", 10),              # missing term
    ("ggx(alpha=0.2))", 15),        # extra ')'
    ("lambert(albedo=0.5 0.4)", 20),  # missing ','
    ("lambert(albedo=[])", 17),     # empty list
    ("lambert @ ggx", 9),           # stray character
    ("ggx(alpha=0.1, 0.2)", 16),    # positional after named
])
def test_syntax_errors_name_the_column(spec, column):
    with pytest.raises(SpecError) as exc:
        brdf.parse(spec)
    assert _column(exc) == column
    assert "expected" in str(exc.value) or "unexpected" in str(exc.value)


@pytest.mark.parametrize("spec, message", [
    ("ggx(alpha=0.1, alpha_x=0.2)", "given twice"),
    ("lambert(0.1, 0.2)", "at most 1 positional"),
    ("ggx(masking=sideways)", "separable, height-correlated"),
    ("ggx(fresnel=fresnell)", "none, schlick, dielectric, conductor"),
    ("ggx(alpha=[0.1,0.2])", "must be a number"),
    # a name where a number belongs: one line naming the column, not float()'s ValueError
    ("lambert(albedo=grey)", r"column 16: albedo expects a number or a \[list\], got 'grey'"),
    ("lambert(grey)", r"column 9: albedo expects a number"),
])
def test_misused_parameters(spec, message):
    with pytest.raises(SpecError, match=message):
        brdf.parse(spec)


@pytest.mark.parametrize("bad", ["", "   ", None, 3.0])
def test_empty_or_non_text_specs(bad):
    with pytest.raises(SpecError):
        brdf.parse(bad)


def test_text_where_a_number_belongs_is_a_parameter_error():
    # from a report's JSON and from Python, as from a spec: not numpy's ValueError
    with pytest.raises(ParameterError, match="albedo must be a number or a list of per-channel "
                                             "numbers, got 'grey'"):
        brdf.from_dict({"model": "lambert", "params": {"albedo": "grey"}})
    with pytest.raises(ParameterError, match=r"alpha must be a number, got \['a'\]"):
        GGX(alpha=["a"])


def test_bad_json():
    with pytest.raises(SpecError, match="line 1 column"):
        brdf.from_json('{"model": "lambert",')
    with pytest.raises(SpecError, match="'model' or 'sum'"):
        brdf.from_dict({"params": {}})
    with pytest.raises(SpecError, match="unknown model"):
        brdf.from_dict({"model": "lamburt"})
