"""No module of the package or the command line imports another module's private names
(``from .scene import _colour``): what a module shares is public API of that module. Private
modules (``from . import _kinds``) are the package's own and may be imported within it."""

import ast
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
SOURCES = sorted([*(ROOT / "brdf").rglob("*.py"), *(ROOT / "cli").rglob("*.py")])


def _is_module(source, node, name):
    """True when ``from <node.module> import name`` names a module file or package."""
    base = source.parent
    for _ in range(max(node.level - 1, 0)):
        base = base.parent
    if node.level == 0:
        parts = (node.module or "").split(".")
        base = ROOT / ("cli" if parts[0] == "brdf_cli" else parts[0])
        parts = parts[1:]
    else:
        parts = node.module.split(".") if node.module else []
    folder = base.joinpath(*parts)
    return (folder / f"{name}.py").exists() or (folder / name / "__init__.py").exists()


def _private_imports(source):
    tree = ast.parse(source.read_text(), filename=str(source))
    for node in ast.walk(tree):
        if isinstance(node, ast.ImportFrom):
            if node.level == 0 and not (node.module or "").startswith(("brdf", "brdf_cli")):
                continue
            for alias in node.names:
                name = alias.name
                if name.startswith("_") and not name.startswith("__") \
                        and not _is_module(source, node, name):
                    yield f"{source.relative_to(ROOT)}:{node.lineno}: {name}"


@pytest.mark.parametrize("source", SOURCES, ids=lambda p: str(p.relative_to(ROOT)))
def test_no_private_names_imported(source):
    found = list(_private_imports(source))
    assert not found, "imports of another module's private names:\n" + "\n".join(found)
