"""The JSON fit report (schema, load_report, reports as CLI materials) and model comparison
(information criteria against an independent likelihood, ranking, the compare command)."""

import json
import math
import re

import numpy as np
import pytest
from scipy import stats

import brdf
from brdf.errors import FormatError, InputError
from brdf.fitting import report as report_module
from brdf.fitting.report import information_criteria
from test_cli import assert_one_error_line, run

TRUTH = "lambert(albedo=0.6) + ggx(alpha=0.25, ks=0.3)"


@pytest.fixture(scope="module")
def table():
    return brdf.measure(TRUTH, "random:600", "relative:0.02", seed=5)


@pytest.fixture(scope="module")
def saved(tmp_path_factory, table):
    folder = tmp_path_factory.mktemp("report")
    data, path = folder / "t.csv", folder / "report.json"
    brdf.write(table, data)
    assert brdf.fit(table, "lambert + ggx(alpha=0.4, ks=0.5)").converged
    from brdf_cli.main import main
    assert main(["fit", str(data), "lambert + ggx(alpha=0.4, ks=0.5)", "-o", str(path),
                 "-q"]) == 0
    return data, path


def test_a_report_loads_back_as_the_fitted_model(saved):
    _, path = saved
    r = brdf.load_report(path)
    doc = json.loads(path.read_text())
    assert r.document == doc and r.params == doc["params"] and r.spec == doc["spec"]
    wi, wo = np.array([[0.3, 0.1, 0.95]]), np.array([[-0.2, 0.4, 0.89]])
    wi, wo = wi / np.linalg.norm(wi), wo / np.linalg.norm(wo)
    assert np.array_equal(r.model.eval(wi, wo), brdf.parse(doc["spec"]).eval(wi, wo))


def test_a_result_saves_the_report_the_command_line_writes(tmp_path, table):
    r = brdf.fit(table, "lambert + ggx(alpha=0.4, ks=0.5)", seed=3)
    path = tmp_path / "r.json"
    r.save(path)
    doc = json.loads(path.read_text())
    doc.pop("timing")
    expected = r.to_dict()
    expected.pop("timing")
    assert doc == json.loads(json.dumps(expected))
    assert brdf.load_report(path).model == r.model
    with pytest.raises(brdf.OutputError, match="exists"):
        r.save(path)
    path.write_text("old")
    r.save(path, force=True)
    assert json.loads(path.read_text())["spec"] == r.spec
    assert [p.name for p in tmp_path.iterdir()] == ["r.json"]  # no temporary file left


def test_the_schema_table_names_every_key_a_report_has(saved):
    documented = re.findall(r"^``(\w+)``", report_module.__doc__, flags=re.M)
    keys = list(json.loads(saved[1].read_text()))
    assert keys[0] == "schema" and keys[-1] == "timing"
    assert set(keys) <= set(documented)
    assert set(documented) - set(keys) <= {"posterior"}   # only with --mcmc


def test_reports_are_materials_on_the_command_line(capsys, saved):
    _, path = saved
    spec = brdf.load_report(path).spec
    code, out, _ = run(capsys, "eval", str(path), "--wi", "30,0", "--wo", "40,180", "--json")
    code2, out2, _ = run(capsys, "eval", spec, "--wi", "30,0", "--wo", "40,180", "--json")
    assert code == code2 == 0
    assert json.loads(out)["f"] == json.loads(out2)["f"]


@pytest.mark.parametrize("text, fragments", [
    ("{not json", ["line 1", "a JSON fit report"]),
    ('{"schema": "brdf.fit/2"}', ["key schema", "'brdf.fit/1', got 'brdf.fit/2'"]),
    ('[1, 2]', ["a JSON object with \"schema\""]),
    ('{"schema": "brdf.fit/1", "spec": "x"}', ["key model", "missing"]),
])
def test_bad_reports_are_one_line_errors(tmp_path, capsys, text, fragments):
    path = tmp_path / "bad.json"
    path.write_text(text)
    with pytest.raises(FormatError) as err:
        brdf.load_report(path)
    for fragment in fragments:
        assert fragment in str(err.value)
    code, _, stderr = run(capsys, "check", str(path))
    assert code == 2
    assert_one_error_line(stderr, str(path), *fragments)


def test_a_report_whose_model_does_not_parse_names_the_key(tmp_path, saved):
    doc = json.loads(saved[1].read_text())
    doc["model"] = {"model": "no-such-model"}
    path = tmp_path / "bad-model.json"
    path.write_text(json.dumps(doc))
    with pytest.raises(FormatError, match=r"bad-model.json:key model: .*no-such-model"):
        brdf.load_report(path)


# --- information criteria ----------------------------------------------------------------------

def test_gaussian_criteria_match_the_maximised_likelihood():
    # l2 residuals with uniform weights: -2 log L at the ML variance, from scipy, differs from
    # n ln L by the constant n (1 + ln 2 pi)
    rng = np.random.default_rng(0)
    r = rng.normal(0.0, 0.03, 500)
    loss = float(np.mean(r * r))
    minus2 = -2.0 * stats.norm.logpdf(r, scale=math.sqrt(loss)).sum()
    ic = information_criteria({"l2": loss}, "l2", len(r), 4)
    assert ic["minus_2_log_likelihood"] + len(r) * (1 + math.log(2 * math.pi)) == \
        pytest.approx(minus2, rel=1e-12)
    assert ic["k"] == 5                                    # the variance is fitted too
    assert ic["aic"] == pytest.approx(ic["minus_2_log_likelihood"] + 10)
    assert ic["bic"] == pytest.approx(ic["minus_2_log_likelihood"] + 5 * math.log(500))


def test_with_stated_sigma_the_criteria_use_chi_square():
    ic = information_criteria({"cosine-l2": 1e-5, "chi-square": 1.1}, "cosine-l2", 1000, 3)
    assert ic["minus_2_log_likelihood"] == pytest.approx(1.1 * 997)
    assert (ic["k"], ic["aic"]) == (3, pytest.approx(1.1 * 997 + 6))


# --- compare -----------------------------------------------------------------------------------

def test_compare_ranks_the_true_family_first(table):
    c = brdf.compare(table, ["lambert", "lambert + beckmann(alpha=0.4, ks=0.5)",
                             "lambert + ggx(alpha=0.4, ks=0.5)"])
    assert c.rows[0]["spec"] == "lambert + ggx(alpha=0.4, ks=0.5)"
    assert [r["aic"] for r in c.rows] == sorted(r["aic"] for r in c.rows)
    assert sum(r["weight"] for r in c.rows) == pytest.approx(1.0)
    assert c.rows[0]["delta"] == 0.0 and c.rows[-1]["spec"] == "lambert"
    assert c.best.spec == c.rows[0]["fitted"]
    assert [r["k"] for r in c.rows] == [3, 3, 1]          # chi-square: sigma is stated
    by_bic = brdf.compare(table, ["lambert", "lambert + ggx(alpha=0.4, ks=0.5)"], by="bic")
    assert by_bic.by == "bic" and by_bic.rows[0]["bic"] <= by_bic.rows[1]["bic"]


def test_compare_options_are_checked(table):
    with pytest.raises(InputError, match="at least two specs"):
        brdf.compare(table, ["lambert"])
    with pytest.raises(InputError, match="criteria: aic, bic"):
        brdf.compare(table, ["lambert", "ggx"], by="waic")


def test_compare_applies_shared_and_fix_to_the_specs_that_have_them():
    rgb = brdf.measure("lambert(albedo=[0.5,0.4,0.3]) + ggx(ks=0.3, alpha=0.3)", "random:300",
                       seed=2)
    c = brdf.compare(rgb, ["lambert", "lambert + ggx(alpha=0.4, ks=0.5)",
                             "lambert + beckmann(alpha=0.4, ks=0.5)"],
                     shared=["ggx.ks"], fix={"ggx.alpha": 0.3, "lambert.albedo[1]": 0.4})
    fits = {r["spec"]: f for r, f in zip(c.rows, c.results)}
    ggx = fits["lambert + ggx(alpha=0.4, ks=0.5)"]
    assert ggx.fixed == {"ggx.alpha": 0.3, "lambert.albedo[1]": 0.4}
    assert "ggx.ks" in ggx.free and "ggx.ks[0]" not in ggx.free  # shared: one value for RGB
    beckmann = fits["lambert + beckmann(alpha=0.4, ks=0.5)"]
    assert beckmann.fixed == {"lambert.albedo[1]": 0.4} and "beckmann.alpha" in beckmann.free
    assert "beckmann.ks[0]" in beckmann.free
    assert fits["lambert"].fixed == {"lambert.albedo[1]": 0.4}


@pytest.mark.parametrize("options", [{"shared": ["ward.alpha"]}, {"fix": {"beta": 1.0}}])
def test_compare_refuses_a_name_that_no_spec_has(table, options):
    with pytest.raises(InputError) as info:
        brdf.compare(table, ["lambert", "lambert + ggx"], **options)
    message = str(info.value)
    assert "in all of the specs" in message and "ggx.alpha" in message
    assert "lambert.albedo" in message and "\n" not in message


def test_cli_compare_prints_the_ranking_and_writes_json(capsys, tmp_path, saved):
    data, _ = saved
    out_path = tmp_path / "cmp.json"
    code, out, err = run(capsys, "compare", str(data), "lambert", "lambert + ggx(alpha=0.4)",
                         "-o", str(out_path))
    assert code == 0, err
    assert "AIC" in out and "best: lambert(" in out
    doc = json.loads(out_path.read_text())
    assert doc["schema"] == "brdf.compare/1" and len(doc["models"]) == 2
    code, _, err = run(capsys, "compare", str(data), "lambert", "ggx", "-o", str(out_path))
    assert code == 2
    assert_one_error_line(err, "exists")
    code, _, err = run(capsys, "compare", str(data), "lambert")
    assert code == 2
    assert_one_error_line(err, "at least two specs")
