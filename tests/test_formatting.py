"""brdf.formatting: numbers for people, four significant digits unless asked otherwise."""

import pytest

from brdf.formatting import round_numbers, significant


@pytest.mark.parametrize("x, text", [(0.4250771409, "0.4251"), (-148120.0, "-1.481e+05"),
                                     (5327.6, "5328"), (1.0, "1"), (0.00016403, "0.000164"),
                                     (7, "7")])
def test_significant_keeps_four_digits(x, text):
    assert significant(x) == text


def test_round_numbers_rounds_decimals_and_leaves_integers_and_names():
    spec = ("lambert(albedo=[0.7544879782952725,0.76957579258923,0.9136]) + "
            "beckmann(ks=1.5e-05, alpha=0.42507714063952307)")
    assert round_numbers(spec) == ("lambert(albedo=[0.7545,0.7696,0.9136]) + "
                                   "beckmann(ks=1.5e-05, alpha=0.4251)")
    # counts, indices, names with digits and version strings are not decimals
    assert round_numbers("1458000 samples, albedo[2], r2, v1.2.3, 9e5ab0, 0.1234567x") == \
        "1458000 samples, albedo[2], r2, v1.2.3, 9e5ab0, 0.1234567x"
    assert round_numbers("0.123456", digits=2) == "0.12"
