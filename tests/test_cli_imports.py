"""What a ``brdf-fit`` command imports: only what it uses (issue 27, a warm command's start).

Each command runs in a fresh interpreter, through ``brdf_cli.main.main`` as the installed script
does, and the test reads ``sys.modules`` at its end. numpy and numba are the floor of any
command that runs a kernel; the libraries below belong to other commands (fitting, plots, the
explorer, batches, images), and importing one costs 0.05-1 s of a command that never calls it.
scipy among them, and PyYAML and ``importlib.metadata``, which numba imports for a version
check, its config file and its extensions (:mod:`brdf._numba_import`).
"""

import json
import subprocess
import sys

import pytest

_RUN = """
import json, sys
from brdf_cli.main import main
try:
    status = main(sys.argv[1:])
except SystemExit as exc:  # --help
    status = exc.code or 0
print(json.dumps({"status": status, "modules": sorted(sys.modules)}))
"""

#: Modules no command below may import: scipy (the optimisers, interpolation), fitting, plots,
#: the explorer, images, HDF5, clusters, what numba reads its config file and extensions with.
FOREIGN = ("scipy", "matplotlib", "pyvista", "vtk", "panel", "bokeh", "PIL", "h5py", "dask",
           "distributed", "nlopt", "emcee", "brdf.fitting", "brdf.viz", "brdf.capture", "yaml",
           "importlib.metadata")


def _printed(tmp_path, source, *argv, flags=()):
    """The JSON that Python source ``source`` prints last, run with arguments ``argv`` in a
    fresh interpreter (with options ``flags``) in ``tmp_path``."""
    done = subprocess.run([sys.executable, *flags, "-c", source, *argv], capture_output=True,
                          text=True, timeout=900, cwd=tmp_path)
    assert done.returncode == 0, done.stderr
    return json.loads(done.stdout.strip().splitlines()[-1])


def _imported(tmp_path, *argv):
    out = _printed(tmp_path, _RUN, *argv)
    return out["status"], set(out["modules"])


def _foreign(modules, allowed=()):
    return sorted(m for m in modules
                  if any(m == f or m.startswith(f + ".") for f in FOREIGN)
                  and not any(m == a or m.startswith(a + ".") for a in allowed))


def test_help_imports_neither_the_library_nor_numba(tmp_path):
    status, modules = _imported(tmp_path, "--help")
    assert status == 0
    assert not {m.split(".")[0] for m in modules} & {"brdf", "numpy", "numba", "scipy"}


def test_check_imports_only_the_model_kernels_and_the_checks(tmp_path):
    status, modules = _imported(tmp_path, "-q", "check", "lambert(albedo=0.5) + ggx(alpha=0.3)")
    assert status in (0, 1)  # the checks ran (1: one failed)
    assert _foreign(modules) == []
    # nor the renderer, the EXR writer, numba's array functions with the BLAS probe, or
    # numpy.ma (which numba's typeof imports to refuse masked arrays)
    assert not {"brdf.render", "OpenEXR", "numba.np.arraymath", "numpy.ma"} & modules
    assert "brdf.properties" in modules  # the test sees the command's own imports


def test_render_imports_only_the_renderer_and_the_exr_writer(tmp_path):
    status, modules = _imported(tmp_path, "-q", "render", "lambert", "--scene", "cornell",
                                "--size", "8x8", "--spp", "1", "-o", str(tmp_path / "c.exr"))
    assert status == 0
    assert _foreign(modules) == []
    assert {"brdf.render", "OpenEXR"} <= modules


_EXTENSIONS = """
import json
import brdf
import numba
from numba.core import entrypoints
brdf.check(brdf.parse("lambert(albedo=0.5)"))
loaded = entrypoints._already_initialized
numba.njit(lambda x: x + 1)(1)  # a compile sets numba's extensions up
print(json.dumps([loaded, entrypoints._already_initialized]))
"""


def test_cached_kernels_leave_numba_extensions_to_the_first_compile(tmp_path):
    """Finding numba's extensions reads every installed distribution's metadata (0.013 s
    with 118 installed); kernels loaded from the cache do not, a compile still does."""
    for _ in range(2):  # the first run compiles the check's kernels if the cache lacks them
        out = _printed(tmp_path, _EXTENSIONS)
    assert out == [False, True]


_CONFIG = """
import json
import brdf
from numba.core import config
print(json.dumps(config.BOUNDSCHECK))
"""


def test_numba_still_reads_its_config_file(tmp_path):
    """numba's reader of ``.numba_config.yaml`` is a stand-in for PyYAML, which a file in the
    working directory has it import."""
    pytest.importorskip("yaml")
    (tmp_path / ".numba_config.yaml").write_text("boundscheck: 1\n")
    assert _printed(tmp_path, _CONFIG, flags=("-W", "error")) == 1


_STAND_INS = """
import json, sys, types
import brdf
imported = {name: name in sys.modules for name in ("yaml", "importlib.metadata")}
import importlib.metadata
import yaml
from numba.core import config, entrypoints
print(json.dumps({"imported": imported,
                  "modules": [type(m) is types.ModuleType for m in (yaml, importlib.metadata)],
                  "numba_reads": [config.yaml.safe_load("a: 1") == {"a": 1},
                                  entrypoints.importlib_metadata.version("numba")
                                  == importlib.metadata.version("numba")]}))
"""


def test_other_imports_get_the_modules_numba_has_stand_ins_for(tmp_path):
    """``import brdf`` imports neither PyYAML nor ``importlib.metadata``; an import of them
    afterwards gets the module itself, and numba's stand-ins read from it."""
    pytest.importorskip("yaml")
    assert _printed(tmp_path, _STAND_INS) == {
        "imported": {"yaml": False, "importlib.metadata": False},
        "modules": [True, True], "numba_reads": [True, True]}
