"""brdf.precompile and brdf.kernel_groups: kernel groups compiled (or loaded) in spawned
processes, the notice before a group first compiles on use, and ``brdf-fit precompile``."""

import json
import os
import re
import subprocess
import sys
from pathlib import Path
from types import SimpleNamespace

import numpy as np
import pytest
from numba.core.event import Event, EventStatus

import brdf
from brdf.kernel_groups import COLD_SECONDS, KERNELS, CompileNotice, group_of
from brdf.precompile import GROUPS, describe, precompile, processes_used, starting
from brdf.progress import reporting
from test_cli import SCRIPT, assert_main_guard_error, assert_one_error_line, run

ROOT = Path(__file__).resolve().parent.parent


def test_groups_run_in_worker_processes_and_report_their_seconds():
    took = precompile(("models", "tables"), processes=2)
    assert list(took) == ["models", "tables"]
    assert all(t["seconds"] > 0.0 and t["compiled"] >= 0 for t in took.values())


def test_an_unknown_group_is_an_input_error():
    with pytest.raises(brdf.InputError, match="unknown kernel group.*models, fitting"):
        precompile(("models", "shaders"))
    assert set(GROUPS) == {"models", "fitting", "tables", "render"}
    assert set(KERNELS) == set(COLD_SECONDS) == set(GROUPS)


def test_the_command_names_a_bad_group_in_one_line(capsys):
    from brdf.precompile import main
    assert main(["render", "nope"]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and "unknown kernel group(s) nope" in err


def test_the_parts_set_how_many_processes_start_and_how_long_a_cold_cache_takes():
    assert all(len(parts) >= 1 and all(seconds > 0 for _, seconds in parts)
               for parts in GROUPS.values())
    assert processes_used(("tables",), 2) == 1
    assert processes_used(("models",), 2) == len(GROUPS["models"]) == 2
    assert processes_used(tuple(GROUPS), 64) == sum(len(p) for p in GROUPS.values())
    total = sum(seconds for parts in GROUPS.values() for _, seconds in parts)
    longest = max(seconds for parts in GROUPS.values() for _, seconds in parts)
    one = starting(tuple(GROUPS), 1)
    assert one.startswith("compiling models, fitting, tables, render in 1 process (about ")
    assert f"about {round(total / 5) * 5} s" in one
    # longest first, each part to the first free process: within one part of an even split
    two = int(re.search(r"about (\d+) s", starting(tuple(GROUPS), 2)).group(1))
    assert total / 2 <= two <= total / 2 + longest


def test_describe_says_compiled_or_loaded():
    assert describe("models", {"seconds": 38.21, "compiled": 41}) == \
        "models: compiled 41 kernels in 38.2 s"
    assert describe("render", {"seconds": 1.04, "compiled": 0}) == \
        "render: loaded from the cache in 1.0 s"


# --- the notice before a group first compiles ------------------------------------------------

def _kernel_modules():
    """Module names of the package's files that compile kernels (import brdf._jit)."""
    uses_jit = re.compile(r"^from \.+_jit import|^import brdf\._jit", re.M)
    for path in sorted((ROOT / "brdf").rglob("*.py")):
        if uses_jit.search(path.read_text(encoding="utf-8")):
            yield ".".join(path.relative_to(ROOT).with_suffix("").parts)


def test_every_kernel_module_belongs_to_a_group():
    modules = list(_kernel_modules())
    assert "brdf.models.lambert" in modules and "brdf.render._integrator" in modules
    assert [m for m in modules if group_of(m) is None] == []
    assert group_of("brdf.models._kernels") == "models"
    assert group_of("brdf.render._materials") == "render"
    assert group_of("brdf.fitting.problem") == "fitting"
    assert group_of("brdf.triangulation") == "tables"
    assert group_of("brdf.samplingx") is None and group_of("numpy.linalg") is None


def compile_event(module, status):
    """numba's ``numba:compile`` event (START or END) of a kernel of ``module``."""
    function = SimpleNamespace(__module__=module)
    return Event("numba:compile", status, data={"dispatcher": SimpleNamespace(py_func=function)})


def _compile(notice, module, status):
    notice.notify(compile_event(module, status))


def _compiling(notice, *modules):
    """Events of a compile of a kernel of ``modules[0]`` within which kernels of the others
    compile (its callees), one after another."""
    _compile(notice, modules[0], EventStatus.START)
    for m in modules[1:]:
        _compile(notice, m, EventStatus.START)
        _compile(notice, m, EventStatus.END)
    _compile(notice, modules[0], EventStatus.END)


def test_one_notice_per_group_and_none_for_callees(capsys):
    notice = CompileNotice()
    with reporting(prog="brdf-fit"):
        _compiling(notice, "brdf.render._integrator", "brdf.models._kernels", "brdf.sampling")
        _compiling(notice, "brdf.render._lights")
        _compiling(notice, "numba.np.arraymath")  # not ours: neither said nor counted
        _compiling(notice, "brdf.models.lambert", "brdf.models.microfacet")
    out, err = capsys.readouterr()
    assert out == "" and err.splitlines() == [
        f"brdf-fit: compiling the renderer's kernels once for this machine "
        f"(up to about {COLD_SECONDS['render']} s) ...",
        f"brdf-fit: compiling the model kernels once for this machine "
        f"(up to about {COLD_SECONDS['models']} s) ..."]
    assert notice.compiled == 6 and notice.announced == {"render", "models"}
    assert notice.depth == 0


def test_quiet_silences_the_notice(capsys):
    notice = CompileNotice()
    with reporting(quiet=True):
        _compiling(notice, "brdf.fitting.problem")
    assert capsys.readouterr() == ("", "") and notice.compiled == 1


def test_no_notice_on_a_warm_cache():
    """The second run of a command loads every kernel from the cache: not a word on stderr
    (the first compiles them if the cache is cold)."""
    for _ in range(2):
        done = subprocess.run([SCRIPT, "eval", "lambert", "--wi", "30,0", "--wo", "30,180"],
                              capture_output=True, text=True, timeout=600)
        assert done.returncode == 0, done.stderr
    assert done.stderr == "" and "0.15915" in done.stdout


@pytest.mark.slow
def test_the_notice_on_a_cold_cache_once(tmp_path):
    """A throwaway cache (numba's own locator for NUMBA_CACHE_DIR before the package's in-tree
    one): the first run compiles and says so in one line, the second loads and is silent."""
    env = {**os.environ, "NUMBA_CACHE_LOCATOR_CLASSES": "UserProvidedCacheLocator",
           "NUMBA_CACHE_DIR": str(tmp_path / "cache")}
    argv = [SCRIPT, "eval", "lambert", "--wi", "30,0", "--wo", "30,180", "--json"]
    cold = subprocess.run(argv, capture_output=True, text=True, timeout=900, env=env)
    assert cold.returncode == 0, cold.stderr
    assert cold.stderr.splitlines() == [
        f"brdf-fit: compiling the model kernels once for this machine "
        f"(up to about {COLD_SECONDS['models']} s) ..."]
    assert json.loads(cold.stdout)["f"]
    assert list((tmp_path / "cache").rglob("*.nbi"))
    warm = subprocess.run(argv, capture_output=True, text=True, timeout=600, env=env)
    assert warm.returncode == 0 and warm.stderr == "" and warm.stdout == cold.stdout


# --- brdf-fit precompile ---------------------------------------------------------------------

def test_the_subcommand_compiles_a_group_and_says_how_long(capsys):
    status, out, err = run(capsys, "precompile", "models", "--json")
    assert status == 0
    data = json.loads(out)
    assert data["processes"] == 2 and list(data["groups"]) == ["models"]  # its two parts
    assert data["groups"]["models"]["seconds"] > 0.0
    assert err.startswith("brdf-fit: precompile: compiling models in 2 processes (about ")
    status, out, err = run(capsys, "precompile", "tables", "--processes", "1")
    assert status == 0 and err.startswith("brdf-fit: precompile: compiling tables")
    assert re.fullmatch(r"tables: (compiled \d+ kernels?|loaded from the cache) in [\d.]+ s\n",
                        out)
    assert run(capsys, "-q", "precompile", "tables") == (0, "", "")


def test_the_subcommand_help_names_every_group(capsys):
    from brdf_cli.precompile import GROUPS_HELP
    assert GROUPS_HELP == ", ".join(GROUPS)  # written out: --help does not import numba
    status, out, _ = run(capsys, "precompile", "--help")
    assert status == 0 and " ".join(GROUPS_HELP.split()) in " ".join(out.split())


@pytest.mark.parametrize("argv, fragments", [
    (["precompile", "models", "shaders"], ["unknown kernel group(s) shaders", "models, fitting"]),
    (["precompile", "--processes", "0"], ["argument --processes", "a process count"]),
    (["precompile", "--processes", "two"], ["argument --processes", "'two'"]),
    (["--quiet=yes", "precompile"], ["--quiet"]),
    (["precompile", "-q=1"], ["-q"]),
])
def test_bad_input_to_the_new_options_is_one_line_and_status_2(capsys, argv, fragments):
    status, out, err = run(capsys, *argv)
    assert status == 2 and out == ""
    assert_one_error_line(err, *fragments)


def test_python_m_brdf_precompile_still_runs():
    done = subprocess.run([sys.executable, "-m", "brdf.precompile", "fitting"],
                          capture_output=True, text=True, timeout=600)
    assert done.returncode == 0, done.stderr
    assert done.stdout.startswith("fitting: ")
    assert done.stderr.startswith("brdf.precompile: compiling fitting in 2 processes")


def test_the_library_calls_no_kernel_only_kernels_call_from_python(monkeypatch):
    """A kernel declared to be called only by kernels (inline, or ``linked=``) has no CPython
    wrapper: a call from Python compiles a twin of it (``brdf._jit``), which no kernel group
    holds, so a user's first such call would compile outside ``brdf-fit precompile``. The
    groups' parts, which run each group's public functions, make no such call."""
    from brdf.precompile import compile_groups

    def run_parts():
        compile_groups(tuple(GROUPS))  # as brdf-fit precompile runs them, in this process

    run_parts()  # first, so that every module they use is imported
    from brdf._jit import DeferredKernel
    calls = []
    # the dispatchers themselves: monkeypatch restores an attribute through the object's own
    # __dict__, which a DeferredKernel's is not, and would delete the twin's hook on undo
    linked = {id(value): value.made() if isinstance(value, DeferredKernel) else value
              for name, module in list(sys.modules.items())
              if name == "brdf" or name.startswith("brdf.")
              for value in list(vars(module).values()) if hasattr(value, "for_python")}
    assert len(linked) > 50
    for dispatcher in linked.values():
        monkeypatch.setattr(dispatcher, "_compile_for_args",
                            lambda *a, d=dispatcher, **k: calls.append(d) or d.for_python())
    run_parts()
    assert [d.py_func.__qualname__ for d in calls] == []
    # and the hook sees a call from Python when one is made
    from brdf.render import _intersect
    assert _intersect.hit_sphere(np.array([0.0, 0.0, 0.0, 1.0]), 0.0, 0.0, 5.0, 0.0, 0.0,
                                 -1.0, 10.0) == 4.0
    assert [d.py_func.__qualname__ for d in calls] == ["hit_sphere"]


def test_a_script_without_the_main_guard_gets_one_line_saying_what_to_add(tmp_path):
    """precompile's workers are spawned: each imports the script again as it starts, which at
    its top level calls precompile again. The workers end quietly and the script gets
    MainGuardError (not BrokenProcessPool after a traceback per worker)."""
    script = tmp_path / "unguarded.py"
    script.write_text("from brdf.precompile import precompile\n"
                      "print(precompile(('tables',), processes=1))\n", encoding="utf-8")
    # the checkout comes first on the subprocess's path (conftest's PYTHONPATH)
    done = subprocess.run([sys.executable, str(script)], capture_output=True, text=True,
                          timeout=600, cwd=tmp_path)
    assert done.stdout == ""
    assert_main_guard_error(done, "unguarded.py", "brdf.precompile.precompile")
