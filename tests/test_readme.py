"""The README is the front door: keep its quick start and command table true."""

import re
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent
README = (ROOT / "README.md").read_text(encoding="utf-8")


def _quick_start():
    section = README[README.index("## Quick start"):README.index("## Command line")]
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
    table = README[README.index("## Command line"):README.index("## A five-minute")]
    missing = [name for name in sub.choices if f"`brdf-fit {name}" not in table]
    assert not missing, missing
