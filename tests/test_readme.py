"""The README is the front door: keep its quick start, command table and links true and the
file short (its examples run in tests/test_docs.py)."""

import re
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent
README = (ROOT / "README.md").read_text(encoding="utf-8")


def _quick_start():
    section = README[README.index("## Quick start"):README.index("## A first real task")]
    return re.findall(r"```sh\n(.+?)\n```", section)


def test_quick_start_is_two_commands_and_ci_runs_the_second_verbatim():
    commands = _quick_start()
    assert len(commands) == 2
    assert commands[0] == "pip install . && brdf-fit demo"
    assert commands[1] in (ROOT / ".ci" / "run").read_text().splitlines()


def test_every_subcommand_is_in_the_command_table():
    from brdf_cli.main import build_parser
    parser = build_parser()
    sub = next(a for a in parser._actions if a.dest == "command")
    table = README[README.index("## Command line"):README.index("## Performance")]
    missing = [name for name in sub.choices if f"`brdf-fit {name}" not in table]
    assert not missing, missing


def test_the_readme_is_a_short_front_door():
    """About 10 KB: what it is, the quick start, one real task, the commands, the headline
    figures and links; reference material lives in docs/."""
    assert len(README.encode("utf-8")) <= 10 * 1024


def test_the_readme_links_resolve():
    links = re.findall(r"\]\(((?:docs|examples|measurements)/[^)#]+)", README)
    assert links
    missing = [link for link in links if not (ROOT / link).exists()]
    assert not missing, missing
