"""brdf.precompile: kernel groups compiled (or loaded) in spawned processes."""

import pytest

import brdf
from brdf.precompile import GROUPS, precompile


def test_groups_run_in_worker_processes_and_report_their_seconds():
    took = precompile(("models", "tables"), processes=2)
    assert list(took) == ["models", "tables"] and all(s > 0.0 for s in took.values())


def test_an_unknown_group_is_an_input_error():
    with pytest.raises(brdf.InputError, match="unknown kernel group.*models, fitting"):
        precompile(("models", "shaders"))
    assert set(GROUPS) == {"models", "fitting", "tables", "render"}


def test_the_command_names_a_bad_group_in_one_line(capsys):
    from brdf.precompile import main
    assert main(["render", "nope"]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and "unknown kernel group(s) nope" in err
