"""The brdf-fit command line: output, JSON, exit statuses and one-line errors.

Most tests call ``main(argv)`` in-process; a few run the installed ``brdf-fit`` script to check
what a shell sees (exit status, a single stderr line, no traceback).
"""

import json
import math
import os
import shutil
import subprocess
import sys

import pytest

import brdf
from brdf.models import MODELS
from brdf_cli.main import main
from fuzzing import without_progress  # noqa: F401  (the CLI tests' helpers live together)

SCRIPT = shutil.which("brdf-fit", path=os.path.dirname(sys.executable)) or "brdf-fit"


def run(capsys, *argv):
    """``(status, stdout, stderr)`` of an in-process run."""
    status = main(list(argv))
    out, err = capsys.readouterr()
    return status, out, err


def run_script(*argv):
    return subprocess.run([SCRIPT, *argv], capture_output=True, text=True, timeout=300)


def assert_one_error_line(err, *fragments):
    lines = err.splitlines()
    assert len(lines) == 1, err
    assert lines[0].startswith("brdf-fit: error: ")
    for fragment in fragments:
        assert fragment in lines[0]


def assert_main_guard_error(done, script, call):
    """``done`` (a finished script without the main guard that made ``call``) ended with
    exit status 1 and MainGuardError's one line, after one traceback (not one per worker and
    ``BrokenProcessPool``)."""
    assert done.returncode == 1
    assert done.stderr.splitlines()[-1] == (
        "brdf.errors.MainGuardError: worker processes stopped as they started: each runs "
        f"the top level of {script} again, so {call} must be called under "
        "'if __name__ == \"__main__\":'")
    assert done.stderr.count("Traceback") == 1
    assert "BrokenProcessPool" not in done.stderr and "bootstrapping" not in done.stderr


# --- help and version ------------------------------------------------------------------------

@pytest.mark.parametrize("argv", [["--help"], ["models", "--help"], ["check", "--help"],
                                  ["eval", "--help"], ["albedo", "--help"]])
def test_help_everywhere(capsys, argv):
    status, out, err = run(capsys, *argv)
    assert status == 0 and out.startswith("usage: brdf-fit") and err == ""
    assert "exit status" in out


def test_version(capsys):
    status, out, _ = run(capsys, "--version")
    assert status == 0 and out.strip() == f"brdf-fit {brdf.__version__}"


# --- models ----------------------------------------------------------------------------------

def test_models_table_lists_every_family_with_its_parameters(capsys):
    status, out, _ = run(capsys, "models")
    assert status == 0
    for cls in MODELS.classes():
        assert any(line.startswith(cls.name) for line in out.splitlines())
        for decl in cls.PARAMS:
            assert any(line.split()[:1] == [decl.name] for line in out.splitlines())
    assert "citation: Lambert 1760" in out
    assert "separable|height-correlated" in out


def test_models_json(capsys):
    status, out, _ = run(capsys, "models", "--json")
    assert status == 0
    data = json.loads(out)
    models = {m["name"]: m for m in data["models"]}
    assert set(models) == set(MODELS.names())
    ggx = {p["name"]: p for p in models["ggx"]["params"]}
    assert ggx["alpha"]["bounds"] == [1e-4, 4.0] and ggx["alpha"]["prior"] == "log"
    assert ggx["ks"]["bounds"] == [0.0, None]  # unbounded above
    assert ggx["ks"]["per_channel"] is True
    assert ggx["alpha_y"]["default"] is None and ggx["alpha_y"]["fallback"] == "alpha"
    assert ggx["masking"]["choices"] == ["separable", "height-correlated"]
    assert "schlick" in ggx["fresnel"]["choices"]
    assert models["lambert"]["aliases"] and models["lambert"]["citation"]
    assert models["phong"]["properties"]["reciprocal"] is False
    assert {f["name"] for f in data["fresnel"]} >= {"none", "schlick"}


# --- check -----------------------------------------------------------------------------------

def test_check_passing_model(capsys):
    status, out, err = run(capsys, "check", "lambert(albedo=0.8)")
    assert status == 0 and err == ""
    assert out.splitlines()[-1] == "result: pass"
    assert [line.split()[0] for line in out.splitlines()[2:5]] == ["non-negativity",
                                                                   "reciprocity", "energy"]


def test_check_failing_model_exits_1_and_says_where(capsys):
    status, out, _ = run(capsys, "check", "lambert(albedo=1) + ggx(alpha=0.5)", "--json")
    assert status == 1
    report = json.loads(out)
    energy = report["checks"][2]
    assert report["passed"] is False and energy["passed"] is False and energy["worst"] > 1
    assert 0 <= energy["where"]["theta_i"] <= 90
    assert len(energy["curve"]["theta_i"]) == 90


def test_check_json_matches_the_library(capsys):
    status, out, _ = run(capsys, "check", "ggx(alpha=0.3)", "--json", "--seed", "3")
    assert status == 0
    assert json.loads(out) == brdf.check("ggx(alpha=0.3)", seed=3).to_dict()


def test_quiet_prints_nothing_but_the_status(capsys):
    assert run(capsys, "--quiet", "check", "phong(n=10)") == (1, "", "")
    assert run(capsys, "check", "lambert", "-q") == (0, "", "")


@pytest.mark.parametrize("spec, fragments", [
    ("nosuch(a=1)", ["unknown model 'nosuch'", "valid:", "lambert", "ggx"]),
    ("lambert(albedo=2)", ["albedo=2", "[0, 1]"]),
    ("ggx(alpha=0.2", ["column", "expected"]),
    ("lambert(colour=1)", ["unknown parameter 'colour'", "albedo"]),
])
def test_bad_spec_is_one_line_and_status_2(capsys, spec, fragments):
    status, out, err = run(capsys, "check", spec)
    assert status == 2 and out == ""
    assert_one_error_line(err, *fragments)


def test_internal_error_is_one_line_and_status_3(capsys, monkeypatch):
    def broken(*args, **kwargs):
        raise ZeroDivisionError("float division by zero")
    monkeypatch.setattr(brdf, "check", broken)
    status, out, err = run(capsys, "check", "lambert")
    assert status == 3 and out == ""
    assert_one_error_line(err, "internal error: ZeroDivisionError", "--debug")
    status, _, err = run(capsys, "check", "lambert", "--debug")
    assert status == 3 and "Traceback" in err and "ZeroDivisionError" in err


# --- eval ------------------------------------------------------------------------------------

def test_eval_prints_each_channel(capsys):
    status, out, _ = run(capsys, "eval", "lambert(albedo=[0.2,0.4,0.8])", "--wi", "30,0",
                         "--wo", "45,90")
    assert status == 0
    rows = [line.split() for line in out.splitlines()[2:]]
    assert [int(r[0]) for r in rows] == [0, 1, 2]
    assert [float(r[1]) for r in rows] == pytest.approx([0.2 / math.pi, 0.4 / math.pi,
                                                         0.8 / math.pi], rel=1e-8)


def test_eval_json_uses_degrees(capsys):
    # mirror configuration: theta_o = theta_i, phi_o = phi_i + 180 (half vector = normal)
    status, out, _ = run(capsys, "eval", "ggx(alpha=0.5)", "--wi", "40,10", "--wo", "40,190",
                         "--json")
    assert status == 0
    data = json.loads(out)
    assert (data["theta_i"], data["phi_i"], data["theta_o"], data["phi_o"]) == (40, 10, 40, 190)
    assert data["units"] == "1/sr"
    t = math.radians(40.0)
    lam = 0.5 * (math.sqrt(1.0 + 0.25 * math.tan(t) ** 2) - 1.0)  # Smith Lambda, GGX
    expected = (1.0 / (math.pi * 0.25)) / (1.0 + lam) ** 2 / (4.0 * math.cos(t) ** 2)
    assert data["f"] == pytest.approx([expected], rel=1e-10)


@pytest.mark.parametrize("option, value, fragments", [
    ("--wi", "95,0", ["argument --wi", "theta 95", "[0, 90]"]),
    ("--wi", "nan,0", ["argument --wi", "not finite"]),
    ("--wo", "abc", ["argument --wo", "THETA,PHI", "'abc'"]),
    ("--wo", "30,abc", ["argument --wo", "phi 'abc' is not a number"]),
    ("--wi", "30", ["argument --wi", "THETA,PHI"]),
])
def test_bad_angles_name_the_option(capsys, option, value, fragments):
    argv = {"--wi": "30,0", "--wo": "30,180", option: value}
    status, out, err = run(capsys, "eval", "lambert", "--wi", argv["--wi"], "--wo", argv["--wo"])
    assert status == 2 and out == ""
    assert_one_error_line(err, *fragments)


# --- albedo ----------------------------------------------------------------------------------

def test_albedo_table_and_json(capsys):
    status, out, _ = run(capsys, "albedo", "lambert(albedo=0.8)")
    assert status == 0
    rows = [line.split() for line in out.splitlines()[2:]]
    assert [float(r[0]) for r in rows] == [0, 30, 60, 89]
    assert all(float(r[2]) == pytest.approx(0.8) for r in rows)

    status, out, _ = run(capsys, "albedo", "ggx(alpha=1)", "--theta-i", "0,45",
                         "--phi-i", "0,90", "--json")
    rows = json.loads(out)["rows"]
    assert [(r["theta_i"], r["phi_i"]) for r in rows] == [(0, 0), (45, 0), (0, 90), (45, 90)]
    assert rows[0]["albedo"][0] == pytest.approx(1.0 - math.log(2.0), abs=1e-3)
    assert 0.0 <= rows[0]["error"][0] < 1e-3


def test_albedo_bad_list_names_the_option(capsys):
    status, _, err = run(capsys, "albedo", "lambert", "--theta-i", "0,30,,60")
    assert status == 2
    assert_one_error_line(err, "argument --theta-i", "'' is not a number")


# --- the installed script --------------------------------------------------------------------

def test_script_bad_spec_single_line_no_traceback():
    proc = run_script("check", "nosuch")
    assert proc.returncode == 2 and proc.stdout == ""
    assert_one_error_line(proc.stderr, "unknown model 'nosuch'", "lambert")
    assert "Traceback" not in proc.stderr


def test_script_bad_angle_and_usage_errors():
    proc = run_script("eval", "lambert", "--wi", "95,0", "--wo", "0,0")
    assert proc.returncode == 2
    assert_one_error_line(proc.stderr, "argument --wi")
    proc = run_script("frobnicate")
    assert proc.returncode == 2
    assert_one_error_line(proc.stderr, "invalid choice", "check")


def test_script_debug_shows_the_traceback():
    proc = run_script("--debug", "check", "lambert(albedo=2)")
    assert proc.returncode == 2
    assert "Traceback" in proc.stderr
    assert proc.stderr.splitlines()[-1].startswith("brdf-fit: error: ")


def test_script_check_statuses_and_json():
    failing = run_script("check", "phong(n=10)", "--json")
    assert failing.returncode == 1 and failing.stderr == ""
    assert json.loads(failing.stdout)["checks"][1]["passed"] is False
    help_ = run_script("--help")
    assert help_.returncode == 0 and "SUBCOMMAND" in help_.stdout


def test_script_output_is_whole_when_the_process_skips_its_teardown(tmp_path):
    # the script ends through os._exit (brdf_cli.process_exit): what it wrote must all arrive,
    # through a pipe and into a file, with the command's status
    proc = run_script("eval", "lambert(albedo=0.5)", "--wi", "0,0", "--wo", "0,0", "--json")
    assert proc.returncode == 0 and json.loads(proc.stdout)
    out = tmp_path / "models.txt"
    with open(out, "w") as f:
        status = subprocess.run([SCRIPT, "models"], stdout=f, timeout=300).returncode
    assert status == 0
    assert out.read_text() == subprocess.run([SCRIPT, "models"], capture_output=True,
                                             text=True, timeout=300).stdout
    assert out.read_text().count("\n") > 10


def _exit_of(code):
    return subprocess.run([sys.executable, "-c", code], capture_output=True, text=True,
                          timeout=60)


_BLAS_THREADS = """
import atexit, os, sys, time
import brdf_cli.main

def report():
    time.sleep(0.3)  # longer than OpenBLAS's default busy wait (2^28 cycles)
    ticks = 0
    for task in os.listdir("/proc/self/task"):
        if int(task) != os.getpid():
            with open(f"/proc/self/task/{task}/stat") as f:
                fields = f.read().rsplit(")", 1)[1].split()
            ticks += int(fields[11]) + int(fields[12])  # user and system clock ticks
    print(os.environ.get("OPENBLAS_THREAD_TIMEOUT"), ticks, file=sys.stderr)

atexit.register(report)
sys.argv = ["brdf-fit", "models"]
brdf_cli.main.run()
"""


@pytest.mark.skipif(not os.path.isdir("/proc/self/task"), reason="no /proc")
def test_the_script_keeps_numpys_blas_threads_from_busy_waiting():
    # the command's other threads (OpenBLAS's, started with numpy) spend no CPU time after
    # numpy's import; without the setting they spun 0.09-0.1 s each; the user's value stays
    env = {k: v for k, v in os.environ.items() if k != "OPENBLAS_THREAD_TIMEOUT"}
    proc = subprocess.run([sys.executable, "-c", _BLAS_THREADS], env=env, capture_output=True,
                          text=True, timeout=120)
    assert proc.returncode == 0, proc.stderr
    timeout, ticks = proc.stderr.split()[-2:]
    assert timeout == "4" and int(ticks) <= 2, proc.stderr
    proc = subprocess.run([sys.executable, "-c", _BLAS_THREADS], capture_output=True, text=True,
                          env={**env, "OPENBLAS_THREAD_TIMEOUT": "28"}, timeout=120)
    assert proc.returncode == 0 and proc.stderr.split()[-2] == "28", proc.stderr


_GC = """
import gc, os, sys, time
import brdf_cli.main
sys.argv = ["brdf-fit", "models"]
brdf_cli.main.run()
during = gc.isenabled()
pid = os.fork()
if pid == 0:
    os._exit(0 if gc.isenabled() else 1)
child = os.waitpid(pid, 0)[1]
time.sleep(brdf_cli.main.GC_AFTER + 0.5)
print(during, child == 0, gc.isenabled(), file=sys.stderr)
"""


@pytest.mark.skipif(not hasattr(os, "fork"), reason="no fork")
def test_the_script_collects_cycles_only_after_its_start():
    # off while a command starts (its imports), on again GC_AFTER later, and in a forked child
    proc = subprocess.run([sys.executable, "-c", _GC], capture_output=True, text=True,
                          timeout=120)
    assert proc.returncode == 0, proc.stderr
    assert proc.stderr.split()[-3:] == ["False", "True", "True"], proc.stderr


def test_process_exit_runs_after_every_other_exit_handler():
    # armed, the status is the command's and other modules' exit handlers still run first
    proc = _exit_of("import atexit, sys, brdf_cli, logging\n"
                    "from brdf_cli import process_exit\n"
                    "atexit.register(lambda: print('their handler ran', flush=True))\n"
                    "logging.basicConfig(stream=sys.stderr)\n"
                    "logging.getLogger('x').warning('logged')\n"
                    "process_exit.arm(3)\n"
                    "print('unflushed', end='')\n"
                    "sys.exit(0)")
    assert proc.returncode == 3
    assert proc.stdout == "unflushedtheir handler ran\n"
    assert "logged" in proc.stderr
    # not armed (a Python session that imported brdf_cli), the exit is Python's own
    proc = _exit_of("import sys, brdf_cli\nsys.exit(5)")
    assert proc.returncode == 5 and proc.stderr == ""
    proc = _exit_of("import sys, brdf_cli\nfrom brdf_cli import process_exit\n"
                    "process_exit.arm('text')\nsys.exit('text')")
    assert proc.returncode == 1 and proc.stderr == "text\n"
