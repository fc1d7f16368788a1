"""Generated source compiled once and kept beside the bytecode (brdf._generated)."""

import builtins
import os
import sys

import pytest

from brdf import _generated
from brdf.models import _kernels

SOURCE = "def twice(x):\n    return 2 * x\n"


def _run(code):
    space = {}
    exec(code, space)
    return space["twice"](21)


@pytest.fixture
def module_file(tmp_path, monkeypatch):
    monkeypatch.setattr(sys, "dont_write_bytecode", False)
    return str(tmp_path / "made.py")


def test_the_second_use_reads_the_code_the_first_kept(module_file, monkeypatch):
    first = _generated.compiled(SOURCE, module_file)
    path = _generated.cache_path(SOURCE, module_file)
    assert os.path.exists(path) and os.path.dirname(path).endswith("__pycache__")
    mask = os.umask(0)
    os.umask(mask)
    assert os.stat(path).st_mode & 0o777 == 0o666 & ~mask  # readable by all, as a .pyc

    def no_compile(*args, **kwargs):
        raise AssertionError("compiled again")

    monkeypatch.setattr(builtins, "compile", no_compile)
    again = _generated.compiled(SOURCE, module_file)
    assert again.co_filename == module_file and again == first and _run(again) == 42


def test_a_damaged_file_compiles_again_and_is_replaced(module_file):
    _generated.compiled(SOURCE, module_file)
    path = _generated.cache_path(SOURCE, module_file)
    with open(path, "wb") as f:
        f.write(b"\xe3\x00garbage")
    assert _run(_generated.compiled(SOURCE, module_file)) == 42
    with open(path, "rb") as f:
        assert f.read()[:4] != b"\xe3\x00ga"


def test_changed_source_gets_its_own_file_and_the_old_one_goes(module_file):
    _generated.compiled(SOURCE, module_file)
    old = _generated.cache_path(SOURCE, module_file)
    changed = SOURCE.replace("2 *", "3 *")
    new = _generated.cache_path(changed, module_file)
    assert new != old and _generated.cache_path(SOURCE, module_file + "x") != old
    assert _run(_generated.compiled(changed, module_file)) == 63
    assert os.path.exists(new) and not os.path.exists(old)


def test_nothing_is_written_when_python_writes_no_bytecode(module_file, monkeypatch):
    monkeypatch.setattr(sys, "dont_write_bytecode", True)
    assert _run(_generated.compiled(SOURCE, module_file)) == 42
    assert not os.path.exists(_generated.cache_path(SOURCE, module_file))


def test_a_folder_that_cannot_be_written_is_left_as_it_is(module_file, tmp_path):
    # a file where the cache folder would be: no write succeeds, whoever runs the test
    (tmp_path / "__pycache__").write_text("")
    assert _run(_generated.compiled(SOURCE, module_file)) == 42
    assert (tmp_path / "__pycache__").read_text() == "" and len(os.listdir(tmp_path)) == 1


def test_the_models_dispatchers_come_from_their_generated_source():
    code = _generated.compiled(_kernels.DISPATCH_SOURCE, _kernels.__file__)
    assert code.co_filename == _kernels.__file__
    names = {c.co_name for c in code.co_consts if isinstance(c, type(code))}
    assert {"lobe_eval", "lobe_sample", "lobe_pdf"} <= names
    assert _kernels.lobe_eval.py_func.__code__.co_filename == _kernels.__file__
