"""brdf.batch: one report per file, resume, a bad file among good ones, a Dask cluster."""

import json
import subprocess
import sys

import pytest

import brdf
from test_cli import assert_main_guard_error

SPEC = "lambert + ggx(alpha=0.4, ks=0.5)"


@pytest.fixture
def folder(tmp_path):
    for i, albedo in enumerate((0.3, 0.5)):
        brdf.write(brdf.measure(f"lambert(albedo={albedo}) + ggx(alpha=0.3, ks=0.2)",
                                "random:200", seed=i), tmp_path / f"t{i}.csv")
    (tmp_path / "bad.csv").write_text("theta_i,phi_i\n1,2\n")
    return tmp_path


def test_batch_fits_each_file_reports_the_bad_one_and_resumes(folder):
    out = folder / "out"
    r = brdf.batch(str(folder / "*.csv"), SPEC, out, jobs=1)
    assert [row["status"] for row in r.rows] == ["failed", "fitted", "fitted"]
    assert "bad.csv" in r.rows[0]["error"] and not r.ok
    assert abs(r.rows[2]["lambert.albedo"] - 0.5) < 1e-3
    report = out / "t1.json"
    assert json.loads(report.read_text())["converged"]
    before = report.read_bytes()
    again = brdf.batch(str(folder / "t*.csv"), SPEC, out, jobs=1)
    assert [row["status"] for row in again.rows] == ["skipped", "skipped"] and again.ok
    assert report.read_bytes() == before
    changed = brdf.batch(str(folder / "t*.csv"), SPEC, out, jobs=1, cutoff=70)
    assert [row["status"] for row in changed.rows] == ["failed", "failed"]
    summary = json.loads((out / "summary.json").read_text())
    assert summary["counts"]["failed"] == 2


def _numbers(path):
    """A report without its timings and its spec strings (the model's parameters, which the
    strings print, stay in the report as numbers)."""
    report = json.loads(path.read_text())
    del report["timing"], report["spec"], report["checks"]["subject"]
    return report


def test_two_local_processes_give_the_reports_of_one(folder):
    one = brdf.batch(str(folder / "t*.csv"), SPEC, folder / "one", jobs=1)
    two = brdf.batch(str(folder / "t*.csv"), SPEC, folder / "two", jobs=2)
    assert [row["status"] for row in two.rows] == ["fitted", "fitted"] and two.ok
    assert [row["file"] for row in two.rows] == [row["file"] for row in one.rows]
    for name in ("t0.json", "t1.json"):
        # Not bit for bit: a worker that compiles a kernel itself and one that loads it from
        # numba's cache may round differently in the last bit (seen on a cold cache: fitted
        # parameters 1e-16 apart, the cubature's error estimates, differences of two rules,
        # 3e-12 apart). One process with one seed does give the same bytes (test_fit.py).
        assert _close(_numbers(folder / "two" / name), _numbers(folder / "one" / name))


def _close(a, b, rtol=1e-9):
    """Equal structures whose floats agree to ``rtol``."""
    if isinstance(a, dict):
        return isinstance(b, dict) and a.keys() == b.keys() and all(_close(a[k], b[k]) for k in a)
    if isinstance(a, list):
        return isinstance(b, list) and len(a) == len(b) and all(map(_close, a, b))
    if isinstance(a, float) and isinstance(b, float):
        return a == b or abs(a - b) <= rtol * max(abs(a), abs(b))
    return a == b


def test_batch_runs_on_a_dask_cluster(folder):
    distributed = pytest.importorskip("dask.distributed")
    with distributed.LocalCluster(n_workers=1, processes=False, threads_per_worker=1,
                                  dashboard_address=None) as cluster:
        r = brdf.batch(str(folder / "t*.csv"), SPEC, folder / "out",
                       scheduler=cluster.scheduler_address)
    assert [row["status"] for row in r.rows] == ["fitted", "fitted"]


def test_a_glob_matching_nothing_is_an_input_error(tmp_path):
    with pytest.raises(brdf.InputError, match="no input file matches"):
        brdf.batch(str(tmp_path / "*.binary"), SPEC, tmp_path / "out")


# --- a script without the main guard ----------------------------------------------------------

SCRIPT = """import sys
import brdf

result = brdf.batch(sys.argv[1], "lambert", sys.argv[2], jobs=2, starts=1, progress=False)
print("statuses", *[row["status"] for row in result.rows])
"""


def _script(folder, guarded):
    body = SCRIPT if not guarded else SCRIPT.replace(
        "\nresult", '\nif __name__ == "__main__":\n    result').replace("\nprint", "\n    print")
    path = folder / ("guarded.py" if guarded else "unguarded.py")
    path.write_text(body, encoding="utf-8")
    return subprocess.run([sys.executable, str(path), str(folder / "t*.csv"), str(folder / "out")],
                          capture_output=True, text=True, timeout=600, cwd=folder)


def test_a_script_without_the_main_guard_gets_one_line_saying_what_to_add(folder):
    """batch's workers are spawned: each imports the script again as it starts, which at its
    top level calls batch again. The workers end quietly and the script gets MainGuardError
    (not BrokenProcessPool after a traceback per worker)."""
    done = _script(folder, guarded=False)
    assert "statuses" not in done.stdout
    assert_main_guard_error(done, "unguarded.py", "brdf.batch")
    assert not (folder / "out" / "t0.json").exists()


def test_the_same_script_with_the_main_guard_runs(folder):
    done = _script(folder, guarded=True)
    assert done.returncode == 0, done.stderr
    assert done.stdout.split() == ["statuses", "fitted", "fitted"]
    # the script and its workers import the installed package, whose kernels may still be
    # uncompiled here (the suite compiles the checkout's): their notices are the only lines
    assert all(line.startswith("brdf: compiling ") for line in done.stderr.splitlines()), \
        done.stderr


def test_workers_failing_earlier_in_the_script_get_the_same_line(folder):
    """Here the workers stop at the script's own work before the call (writing a file that the
    parent wrote, without force): their tracebacks are the script's, and the last line still
    says what to add."""
    path = folder / "writes_first.py"
    path.write_text(SCRIPT.replace("\nresult", '\nbrdf.write(brdf.read("t0.csv"), "copy.csv")'
                                                '\nresult'), encoding="utf-8")
    done = subprocess.run([sys.executable, str(path), str(folder / "t*.csv"),
                           str(folder / "out")], capture_output=True, text=True, timeout=600,
                          cwd=folder)
    assert done.returncode == 1 and "statuses" not in done.stdout
    assert done.stderr.splitlines()[-1].startswith("brdf.errors.MainGuardError: worker processes "
                                                   "stopped as they started")
