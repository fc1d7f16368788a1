"""The README and the documentation: every example runs as written, and the site builds
without a warning.

Examples are the fenced blocks of the Markdown pages, run in order per page in a fresh folder
that holds the checkout's ``measurements/`` (Sybil parses the pages):

- ``python`` blocks run in one namespace per page (``__name__`` is ``"__main__"``, as in a
  script);
- ``console`` blocks run each ``$ `` line with bash; a line carries a comment ``# exit N``
  (text may follow) where its exit status is not 0, and the status must be the one written;
- ``toml``, ``json`` and ``text`` blocks whose first line is ``# file: NAME`` (TOML) or that
  follow a ``<!-- file: NAME -->`` comment are written to that file, for the examples after
  them;
- ``sh`` blocks are installation commands, which CI runs itself (``.ci/run``), and other
  languages are shown only.
"""

import os
import re
import subprocess
import sys
from pathlib import Path

import pytest
from sybil import Sybil
from sybil.parsers.markdown import CodeBlockParser, PythonCodeBlockParser

ROOT = Path(__file__).resolve().parent.parent
PAGES = [ROOT / "README.md"] + sorted((ROOT / "docs").rglob("*.md"))
EXIT = re.compile(r"#\s*exit\s+(\d+)\b")
FILE = re.compile(r"^#\s*file:\s*(\S+)\s*\n")


def _commands(text):
    """The ``$ `` lines of a console block, with backslash continuations joined."""
    out, current = [], None
    for line in text.splitlines():
        if current is not None:
            current += "\n" + line
        elif line.startswith("$ "):
            current = line[2:]
        if current is not None and not current.endswith("\\"):
            out.append(current)
            current = None
    return out


def _console(example):
    env = dict(os.environ, PYTHONPATH=os.pathsep.join(
        [str(ROOT), os.environ.get("PYTHONPATH", "")]).rstrip(os.pathsep),
        PATH=os.pathsep.join([os.path.dirname(sys.executable), os.environ.get("PATH", "")]),
        MPLBACKEND="Agg")
    for command in _commands(example.parsed):
        expected = int(EXIT.search(command).group(1)) if EXIT.search(command) else 0
        done = subprocess.run(["bash", "-c", command], capture_output=True, text=True, env=env,
                              timeout=600)
        if done.returncode != expected:
            return (f"$ {command}\nexit {done.returncode}, expected {expected}\n"
                    f"{done.stdout[-2000:]}{done.stderr[-2000:]}")
    return None


def _file(example):
    text = example.parsed
    name = FILE.match(text)
    if name is None:
        before = example.document.text[:example.start].rstrip().splitlines()
        marker = re.match(r"<!--\s*file:\s*(\S+)\s*-->", before[-1]) if before else None
        if marker is None:
            return None  # shown only
        Path(marker.group(1)).write_text(text, encoding="utf-8")
    else:
        Path(name.group(1)).write_text(text[name.end():], encoding="utf-8")
    return None


SYBIL = Sybil(parsers=[PythonCodeBlockParser(), CodeBlockParser("console", _console),
                       CodeBlockParser("toml", _file), CodeBlockParser("json", _file),
                       CodeBlockParser("text", _file)])


def test_every_page_is_found():
    assert len(PAGES) >= 10, PAGES


@pytest.mark.parametrize("page", PAGES, ids=lambda p: str(p.relative_to(ROOT)))
def test_examples_run_as_written(page, tmp_path, monkeypatch):
    monkeypatch.chdir(tmp_path)
    (tmp_path / "measurements").symlink_to(ROOT / "measurements")
    monkeypatch.setenv("MPLBACKEND", "Agg")
    document = SYBIL.parse(page)
    document.namespace["__name__"] = "__main__"  # a page's Python runs as a script would
    for example in document:
        example.evaluate()


def test_the_site_builds_without_warnings(tmp_path):
    done = subprocess.run([sys.executable, "-m", "sphinx", "-W", "--keep-going", "-q", "-b",
                           "html", str(ROOT / "docs"), str(tmp_path / "html")],
                          capture_output=True, text=True, timeout=900)
    assert done.returncode == 0, done.stderr[-5000:]
    # docutils' own messages (help texts parsed as reStructuredText) and numpydoc's section
    # warnings bypass -W: hold them too
    assert "WARNING" not in done.stderr and "ERROR" not in done.stderr, done.stderr[-5000:]
    assert "UserWarning" not in done.stderr, done.stderr[-5000:]
    assert (tmp_path / "html" / "index.html").is_file()
    assert (tmp_path / "html" / "cli.html").is_file()
